// The MPI build's cutting and merging (src/mpi/top_pairs.h, share.h, shard_file.h), with the
// ranks simulated in one process: no MPI needed. The oracle is the single-process build_vmap.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "mpi/shard_file.h"
#include "mpi/share.h"
#include "mpi/top_pairs.h"
#include "test_files.h"
#include "test_util.h"
#include "vmap/build_parts.h"
#include "vmap/error.h"

namespace vmap {
namespace {

using mpi::NodePair;

struct Case {
    const char* scene;
    int points, height, leaf_points;
};
const Case kCases[] = {{"cornell-bunny", 1000, 6, 1},
                       {"test/test-plates", 1000, 6, 2},
                       {"test/test-many", 1000, 5, 1}};

// What `ranks` processes of an MPI build would give, each part built on its own, merged as
// mpi_build.cpp does (jobs: 0 the probe's split for `ranks`, else that largest job area).
std::vector<NodePair> shared_links(const PointSet& pts, const BuildParams& bp, int ranks,
                                   bool guided, uint64_t max_area, VisibilityMap& vm) {
    mpi::TopPairs tp;
    BuildStats st;
    vm = mpi::probe(pts, bp, ranks, tp, st, "test");
    if (max_area) tp = mpi::make_top_pairs(vm.octree(), max_area);
    const auto parts = guided ? mpi::dynamic_chunks(tp, ranks) : mpi::static_shares(tp, ranks);
    // Guided: each simulated rank takes every ranks-th chunk, all in one build (build_rounds,
    // as a rank of the dynamic schedule does); static: one build of its share each.
    const size_t procs = guided ? size_t(ranks) : parts.size();
    std::vector<mpi::ShareResult> got(procs);
    std::vector<uint8_t> full(tp.pairs.size(), 0);
    for (size_t k = 0; k < procs; ++k) {
        if (guided) {
            size_t next = k;
            mpi::build_rounds(
                vm, bp, tp,
                [&]() -> const std::vector<uint32_t>* {
                    if (next >= parts.size()) return nullptr;
                    next += procs;
                    return &parts[next - procs];
                },
                true, "test", got[k]);
            EXPECT_EQ(got[k].rounds, int((parts.size() - k + procs - 1) / procs));
        } else {
            mpi::build_round(vm, bp, tp, parts[k], true, "test", got[k]);
        }
        for (size_t i = 0; i < full.size(); ++i)
            full[i] |= got[k].full.size() > i && got[k].full[i];
    }
    const mpi::Merge m = mpi::merge_full(tp, full);
    std::vector<NodePair> links = m.add;
    for (auto& g : got) {
        mpi::drop_merged(tp, m, g.links);
        links.insert(links.end(), g.links.begin(), g.links.end());
    }
    return links;
}

void expect_same_links(const VisibilityMap& want, const VisibilityMap& got) {
    ASSERT_EQ(want.link_offsets(), got.link_offsets());
    ASSERT_TRUE(std::equal(want.link_targets().begin(), want.link_targets().end(),
                           got.link_targets().begin(), got.link_targets().end()));
}

TEST(MpiSplit, JobsCoverEveryLeafPairOnce) {
    const Case& c = kCases[0];
    PointSet pts = test::sample(test::scene_path(c.scene), c.points);
    std::vector<uint32_t> order;
    const Octree t = Octree::build_in_unit_frame(pts, {c.height, c.leaf_points}, order);
    for (uint64_t max_area : {uint64_t(1), uint64_t(100), uint64_t(1) << 40}) {
        const mpi::TopPairs tp = mpi::make_top_pairs(t, max_area);
        const int32_t l = t.num_leaves();
        std::vector<uint8_t> seen(size_t(l) * l, 0);
        for (uint32_t j : tp.jobs) {
            const mpi::TopPair& p = tp.pairs[j];
            EXPECT_TRUE(p.area <= max_area || (t.is_leaf(p.a) && t.is_leaf(p.b)));
            for (int32_t r = t.leaf_begin()[p.a]; r < t.leaf_end()[p.a]; ++r)
                for (int32_t q = t.leaf_begin()[p.b]; q < t.leaf_end()[p.b]; ++q) {
                    ASSERT_LT(r, q);
                    ASSERT_EQ(seen[size_t(r) * l + q]++, 0) << "leaf pair in two jobs";
                }
        }
        uint64_t covered = 0;
        for (uint8_t s : seen) covered += s;
        EXPECT_EQ(covered, uint64_t(l) * (l - 1) / 2);
    }
}

TEST(MpiSplit, SharesAndChunksHoldEveryJobOnce) {
    PointSet pts = test::sample(test::scene_path("cornell-bunny"), 2000);
    std::vector<uint32_t> order;
    const Octree t = Octree::build_in_unit_frame(pts, {6, 1}, order);
    const mpi::TopPairs tp = mpi::make_top_pairs_for(t, 4);
    for (const auto& parts : {mpi::static_shares(tp, 4), mpi::dynamic_chunks(tp, 4)}) {
        std::vector<uint32_t> all;
        for (const auto& p : parts) all.insert(all.end(), p.begin(), p.end());
        std::sort(all.begin(), all.end());
        EXPECT_EQ(all, tp.jobs);
    }
    // The estimate splits evenly: no share far above the mean.
    const auto shares = mpi::static_shares(tp, 4);
    uint64_t hi = 0;
    for (const auto& s : shares) {
        uint64_t a = 0;
        for (uint32_t j : s) a += tp.pairs[j].area;
        hi = std::max(hi, a);
    }
    EXPECT_LT(double(hi), 1.1 * double(tp.total_area) / 4);
}

// Every split of the work, merged, gives the single-process map exactly; max_area 1 splits
// every pair down to leaf pairs, so every full node pair is rebuilt by merges alone.
TEST(MpiSplit, SimulatedRanksGiveTheSingleProcessMap) {
    for (const Case& c : kCases) {
        SCOPED_TRACE(c.scene);
        const PointSet pts = test::sample(test::scene_path(c.scene), c.points);
        const BuildParams bp = test::cpu_params(c.height, c.leaf_points);
        const VisibilityMap want = build_vmap(pts, bp);
        for (auto [ranks, guided, max_area] :
             {std::tuple{2, false, uint64_t(0)}, std::tuple{3, true, uint64_t(0)},
              std::tuple{5, false, uint64_t(1)}, std::tuple{4, true, uint64_t(37)}}) {
            VisibilityMap vm;
            set_links(vm, {});  // replaced below
            std::vector<NodePair> links = shared_links(pts, bp, ranks, guided, max_area, vm);
            set_links(vm, std::move(links));
            expect_same_links(want, vm);
        }
    }
}

// The MPI build builds the octree once (the probe) and resolves its share over it
// (build_links): the saved file is byte for byte build_vmap's, on points without radii (the
// probe estimates them) too, and the rounds give the probe's map back as it was, no links.
TEST(MpiSplit, TheProbesOctreeReusedGivesTheSameFile) {
    PointSet pts = test::sample(test::scene_path("cornell-bunny"), 1200);
    pts.radii.clear();
    const BuildParams bp = test::cpu_params(6, 1);
    test::ScratchDir dir;
    save_vmap(dir.path("a.vmap"), build_vmap(pts, bp));
    BuildStats st;
    VisibilityMap base = detail::build_octree(pts, bp, st, "test");
    EXPECT_FALSE(base.has_links());
    EXPECT_GT(st.seconds_octree, 0);
    const std::vector<float> radii = base.points().radii;
    ASSERT_EQ(radii.size(), pts.size());
    save_vmap(dir.path("b.vmap"), detail::build_links(base, bp, nullptr, "test"));
    EXPECT_EQ(test::slurp(dir.path("a.vmap")), test::slurp(dir.path("b.vmap")));

    mpi::TopPairs tp;
    VisibilityMap vm = mpi::probe(pts, bp, 2, tp, st, "test");
    mpi::ShareResult got;
    mpi::build_round(vm, bp, tp, tp.jobs, true, "test", got);
    EXPECT_FALSE(vm.has_links());
    EXPECT_EQ(vm.points().radii, radii);
    EXPECT_EQ(vm.octree().num_nodes(), base.octree().num_nodes());
    const mpi::Merge m = mpi::merge_full(tp, got.full);
    std::vector<NodePair> links = m.add;
    mpi::drop_merged(tp, m, got.links);
    links.insert(links.end(), got.links.begin(), got.links.end());
    set_links(vm, std::move(links));
    save_vmap(dir.path("c.vmap"), vm);
    EXPECT_EQ(test::slurp(dir.path("a.vmap")), test::slurp(dir.path("c.vmap")));
}

// A rank of the dynamic schedule resolves every chunk it is handed in one build; an empty
// chunk (more bins than jobs) must not end its rounds, or the chunks after it would be lost.
TEST(MpiSplit, EmptyChunksDoNotEndARanksRounds) {
    const PointSet pts = test::sample(test::scene_path("cornell-bunny"), 1000);
    const BuildParams bp = test::cpu_params(6, 1);
    const VisibilityMap want = build_vmap(pts, bp);
    mpi::TopPairs tp;
    BuildStats st;
    VisibilityMap vm = mpi::probe(pts, bp, 1, tp, st, "test");
    const auto two = mpi::static_shares(tp, 2);
    const std::vector<std::vector<uint32_t>> chunks{{}, two[0], {}, {}, two[1], {}};
    size_t next = 0;
    mpi::ShareResult got;
    mpi::build_rounds(
        vm, bp, tp,
        [&]() -> const std::vector<uint32_t>* {
            return next < chunks.size() ? &chunks[next++] : nullptr;
        },
        true, "test", got);
    EXPECT_EQ(next, chunks.size());
    EXPECT_EQ(got.rounds, int(chunks.size()));
    const mpi::Merge m = mpi::merge_full(tp, got.full);
    std::vector<NodePair> links = m.add;
    mpi::drop_merged(tp, m, got.links);
    links.insert(links.end(), got.links.begin(), got.links.end());
    set_links(vm, std::move(links));
    expect_same_links(want, vm);
}

// The node ranges of the sharded output, laid end to end, are the one-file arrays.
TEST(MpiSplit, NodeRangesConcatenateToTheLinkArrays) {
    const PointSet pts = test::sample(test::scene_path("cornell-bunny"), 1500);
    const VisibilityMap want = build_vmap(pts, test::cpu_params(6, 1));
    std::vector<NodePair> links;
    std::vector<uint32_t> deg(size_t(want.octree().num_nodes()), 0);
    for (int32_t n = 0; n < want.octree().num_nodes(); ++n)
        for (int32_t m : want.links(n)) {
            deg[n]++;
            if (m > n) links.emplace_back(m, n);  // either orientation
        }
    for (int parts : {1, 2, 7}) {
        const std::vector<int32_t> b = mpi::split_nodes(deg, parts);
        ASSERT_EQ(b.size(), size_t(parts) + 1);
        EXPECT_EQ(b.front(), 0);
        EXPECT_EQ(b.back(), want.octree().num_nodes());
        std::vector<uint64_t> off{0};
        std::vector<int32_t> tg;
        for (int k = 0; k < parts; ++k) {
            ASSERT_LE(b[k], b[k + 1]);
            const mpi::LinkRange r = mpi::link_range(links, b[k], b[k + 1]);
            for (size_t i = 1; i < r.offsets.size(); ++i) off.push_back(tg.size() + r.offsets[i]);
            tg.insert(tg.end(), r.targets.begin(), r.targets.end());
        }
        EXPECT_EQ(off, want.link_offsets());
        EXPECT_TRUE(std::equal(tg.begin(), tg.end(), want.link_targets().begin(),
                               want.link_targets().end()));
        // The links cut by owner, in parallel blocks: the serial loop's lists, in its order.
        std::vector<std::vector<NodePair>> serial(static_cast<size_t>(parts));
        auto owner = [&](int32_t n) {
            return size_t(std::upper_bound(b.begin(), b.end(), n) - b.begin()) - 1;
        };
        for (const NodePair& l : links) {
            serial[owner(l.first)].push_back(l);
            if (owner(l.second) != owner(l.first)) serial[owner(l.second)].push_back(l);
        }
        EXPECT_EQ(mpi::by_owner(links, b), serial);
    }
    // More threads than the machine's cores, and one: the same ranges (the threads split the
    // nodes among them).
    for (int threads : {1, 5}) {
        tbb::task_arena arena(threads);
        arena.execute([&] {
            const mpi::LinkRange r = mpi::link_range(links, 0, want.octree().num_nodes());
            EXPECT_EQ(r.offsets, want.link_offsets());
            EXPECT_TRUE(std::equal(r.targets.begin(), r.targets.end(), want.link_targets().begin(),
                                   want.link_targets().end()));
        });
    }
}

class ShardFiles : public ::testing::Test {
  protected:
    std::filesystem::path dir =
        std::filesystem::temp_directory_path() / ("vmap-shards-" + std::to_string(::getpid()));
    void SetUp() override { std::filesystem::create_directories(dir); }
    void TearDown() override { std::filesystem::remove_all(dir); }

    // want's links as `parts` shards and an index; returns the index's path.
    std::string write(const VisibilityMap& want, int parts) {
        std::vector<uint32_t> deg(size_t(want.octree().num_nodes()), 0);
        for (int32_t n = 0; n < want.octree().num_nodes(); ++n) deg[n] = want.links(n).size();
        return write(want, mpi::split_nodes(deg, parts));
    }
    // The same with the shards' node ranges [b[k], b[k + 1]) given.
    std::string write(const VisibilityMap& want, const std::vector<int32_t>& b) {
        const std::string index = (dir / "m.vmap").string();
        const int parts = int(b.size()) - 1;
        std::vector<NodePair> links;
        for (int32_t n = 0; n < want.octree().num_nodes(); ++n)
            for (int32_t m : want.links(n))
                if (m > n) links.emplace_back(n, m);
        std::vector<mpi::ShardInfo> info(static_cast<size_t>(parts));
        for (int k = 0; k < parts; ++k)
            mpi::write_shard(mpi::shard_name(index, k, parts), k,
                             mpi::link_range(links, b[k], b[k + 1]), info[k])
                ->commit();
        mpi::save_base(mpi::base_name(index), want);
        mpi::write_index(index, info, want.num_links(), want.octree().num_nodes());
        return index;
    }
};

TEST_F(ShardFiles, ReadBackAsTheOneFileMap) {
    const VisibilityMap want =
        build_vmap(test::sample(test::scene_path("cornell-bunny"), 1500), test::cpu_params(6, 1));
    const std::string index = write(want, 3);
    EXPECT_TRUE(mpi::is_shard_index(index));
    const VisibilityMap got = load_vmap(index);
    expect_same_links(want, got);
    EXPECT_EQ(want.order(), got.order());
    EXPECT_EQ(want.octree().skip(), got.octree().skip());
    EXPECT_EQ(got.query(0, 700), want.query(0, 700));
}

// A shard of no nodes, so no links (the fuzz target's finding: its empty array was copied
// from a null pointer, undefined behaviour that the debug build's UBSan stops).
TEST_F(ShardFiles, AShardOfNoNodesLoads) {
    const VisibilityMap want =
        build_vmap(test::sample(test::scene_path("cornell-bunny"), 400), test::cpu_params(4, 2));
    const int32_t nodes = want.octree().num_nodes();
    const VisibilityMap got = load_vmap(write(want, {0, nodes / 2, nodes / 2, nodes}));
    expect_same_links(want, got);
}

TEST_F(ShardFiles, MissingOrCorruptShardIsNamed) {
    const VisibilityMap want =
        build_vmap(test::sample(test::scene_path("cornell-bunny"), 1200), test::cpu_params(5, 1));
    const std::string index = write(want, 2);
    const std::string shard = mpi::shard_name(index, 1, 2);
    {  // one byte flipped in the targets
        std::fstream f(shard, std::ios::in | std::ios::out | std::ios::binary);
        f.seekg(-3, std::ios::end);
        char x = 0;
        f.read(&x, 1);
        f.seekp(-3, std::ios::end);
        x ^= 1;
        f.write(&x, 1);
    }
    try {
        load_vmap(index);
        FAIL() << "a corrupt shard loaded";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("shard-1-of-2: checksum mismatch"), std::string::npos)
            << e.what();
    }
    std::filesystem::remove(shard);
    EXPECT_THROW(load_vmap(index), Error);
}

// What the fuzz target fuzz/fuzz_shards.cpp found, or would have: each damaged index or shard is
// a vmap::Error naming the field, never a crash, a recursion or another exception type.
class DamagedShards : public ShardFiles {
  protected:
    std::string index;
    nlohmann::json j;
    void SetUp() override {
        ShardFiles::SetUp();
        index = write(build_vmap(test::sample(test::scene_path("cornell-bunny"), 300),
                                 test::cpu_params(4, 2)),
                      2);
        j = nlohmann::json::parse(std::ifstream(index));
    }
    // The index rewritten with `edit` applied; the load's error message.
    template <class F>
    std::string error_after(F&& edit) {
        nlohmann::json k = j;
        edit(k);
        std::ofstream(index) << k.dump(1);
        try {
            load_vmap(index);
        } catch (const Error& e) {
            return e.what();
        }
        return "no error";
    }
};

TEST_F(DamagedShards, AnIndexNamingItselfAsItsBaseIsAnErrorNotARecursion) {
    EXPECT_NE(error_after([](auto& k) { k["base"] = "m.vmap"; }).find("not a .vmap"),
              std::string::npos);
}

TEST_F(DamagedShards, BadFieldsOfTheIndexAreNamed) {
    auto has = [](const std::string& msg, const char* part) {
        return msg.find(part) != std::string::npos;
    };
    EXPECT_TRUE(has(error_after([](auto& k) { k["shards"][0]["checksum"] = "zz"; }),
                    "shard 0: \"checksum\": \"zz\" is not 16 hex digits"));
    EXPECT_TRUE(has(error_after([](auto& k) { k["nodes"] = 1e300; }),
                    "\"nodes\": an integer expected"));
    EXPECT_TRUE(has(error_after([](auto& k) { k["shards"][1]["nodes"][1] = 1 << 30; }),
                    "shard 1: \"nodes\": 1073741824 is outside"));
    EXPECT_TRUE(has(error_after([](auto& k) { k["shards"][0]["nodes"][0] = -1; }),
                    "shard 0: \"nodes\": -1 is outside"));
    EXPECT_TRUE(has(error_after([](auto& k) { k["shards"][0]["file"] = "../m.vmap.base"; }),
                    "is not a file name in the index's folder"));
    EXPECT_TRUE(has(error_after([](auto& k) { k["version"] = "1"; }), "an integer expected"));
}

TEST_F(DamagedShards, TargetCountsThatOverflowTheLengthCheckAreRefused) {
    // ends + 2^62 links: 4 bytes each wraps to the true length, in the header and the index.
    const std::string shard = mpi::shard_name(index, 0, 2);
    const uint64_t ends = j["shards"][0]["ends"].get<uint64_t>() + (uint64_t(1) << 62);
    {
        std::fstream f(shard, std::ios::in | std::ios::out | std::ios::binary);
        f.seekp(24);
        f.write(reinterpret_cast<const char*>(&ends), 8);
    }
    EXPECT_NE(error_after([&](auto& k) { k["shards"][0]["ends"] = ends; })
                  .find("shard-0-of-2: length does not match its header"),
              std::string::npos);
}

}  // namespace
}  // namespace vmap
