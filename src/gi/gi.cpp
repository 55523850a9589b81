// Hierarchical radiosity over the V-map (paper §6.3; the contract is in include/vmap/gi.h).
#include "vmap/gi.h"

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <numbers>
#include <span>

#include "gi/gi_device.h"
#include "gi/gi_hier.h"
#include "gi/gi_host.h"
#include "gi/gi_kernels.h"
#include "util/device.h"
#include "util/huge_array.h"
#include "util/progress.h"
#include "vmap/error.h"
#include "vmap/parallel.h"

namespace vmap {
namespace {

using Clock = std::chrono::steady_clock;
constexpr float kPi = std::numbers::pi_v<float>;
const Vec3 kDefaultAlbedo{0.8f, 0.8f, 0.8f};

void check_points(const VisibilityMap& vm, const char* who) {
    const PointSet& ps = vm.points();
    if (ps.size() == 0) throw Error(fmt::format("{}: the V-map has no points", who));
    if (!ps.has_normals() || ps.normals.size() != ps.size())
        throw Error(fmt::format("{}: points: normals are required", who));
    if (!ps.has_radii() || ps.radii.size() != ps.size())
        throw Error(fmt::format(
            "{}: points: splat radii are required (each point stands for a disc of that radius)",
            who));
    if (ps.has_colors() && ps.colors.size() != ps.size())
        throw Error(
            fmt::format("{}: points: {} colours for {} points", who, ps.colors.size(), ps.size()));
    if (!ps.emission.empty() && ps.emission.size() != ps.size())
        throw Error(fmt::format("{}: points: {} emission values for {} points", who,
                                ps.emission.size(), ps.size()));
    if (vm.octree().num_nodes() == 0 ||
        vm.link_offsets().size() != size_t(vm.octree().num_nodes()) + 1)
        throw Error(fmt::format("{}: the V-map has no octree or links", who));
}

Vec3 albedo_of(const PointSet& ps, size_t i) {
    return ps.has_colors() ? ps.colors[i] : kDefaultAlbedo;
}
Vec3 emission_of(const PointSet& ps, size_t i) {
    return ps.emission.empty() ? Vec3{} : ps.emission[i];
}
float area_of(const PointSet& ps, size_t i) { return kPi * ps.radii[i] * ps.radii[i]; }

// Every point pair (i, j) of leaves a x b (octree positions) whose kernel is positive:
// f(i, j, area_i, area_j, kernel).
template <class F>
void for_point_pairs(const VisibilityMap& vm, int32_t a, int32_t b, F&& f) {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    for (uint32_t i = t.point_begin()[a]; i < t.point_end()[a]; ++i)
        for (uint32_t j = t.point_begin()[b]; j < t.point_end()[b]; ++j) {
            const float ai = area_of(ps, i), aj = area_of(ps, j);
            const float k =
                gi_kernel(ps.positions[i], ps.normals[i], ai, ps.positions[j], ps.normals[j], aj);
            if (k > 0) f(i, j, ai, aj, k);
        }
}

using detail::NodeGeom;

// `--refine links`: refines every V-map link into receiver/source interactions; calls
// emit(recv, src, F, point_level) for each (both directions). Elements: nodes, then points at
// num_nodes + k.
struct Refiner {
    const VisibilityMap& vm;
    const std::vector<NodeGeom>& g;
    float theta;

    template <class Emit>
    void refine(int32_t a, int32_t b, Emit& emit) const {
        const Octree& t = vm.octree();
        const NodeGeom &ga = g[a], &gb = g[b];
        const float d = length(gb.center - ga.center);
        if (d > theta * (ga.size + gb.size)) {
            // The regulariser is the points' typical area, not the node's: the node-level
            // transfer stands for the sum of its point pairs' (whose denominators are
            // pi d^2 + a point's area). Well separated flat content keeps A_B < pi d^2 /
            // theta^2; the cap at 1 only guards crumpled content in a small box.
            const float k =
                gi_kernel(ga.center, ga.normal, ga.point_area, gb.center, gb.normal, gb.point_area);
            if (k > 0) {
                emit(uint32_t(a), uint32_t(b), std::min(1.0f, k * gb.area), false);
                emit(uint32_t(b), uint32_t(a), std::min(1.0f, k * ga.area), false);
            }
            return;
        }
        const bool la = t.is_leaf(a), lb = t.is_leaf(b);
        if (la && lb) {
            const uint32_t base = uint32_t(t.num_nodes());
            for_point_pairs(vm, a, b, [&](uint32_t i, uint32_t j, float ai, float aj, float k) {
                emit(base + i, base + j, k * aj, true);
                emit(base + j, base + i, k * ai, true);
            });
            return;
        }
        // Open the larger node (a leaf cannot be opened): its children all see the other node.
        if (lb || (!la && ga.size >= gb.size))
            t.for_each_child(a, [&](int32_t c) { refine(c, b, emit); });
        else
            t.for_each_child(b, [&](int32_t c) { refine(a, c, emit); });
    }

    // Every link once (a < b).
    template <class MakeEmit>
    void run(MakeEmit&& make_emit) const {
        parallel_for_range<int32_t>(vm.octree().num_nodes(), 1,
                                    [&](int32_t chunk_begin, int32_t chunk_end) {
                                        auto emit = make_emit();
                                        for (int32_t a = chunk_begin; a < chunk_end; ++a)
                                            for (int32_t b : vm.links(a))
                                                if (b > a) refine(a, b, emit);
                                    });
    }
};

// Refinement by blocks (the default; the partition and the weights are docs/gi.md's, one link's
// share is detail::gi_link_blocks). The blocks, sorted by key, each with the sum of its parts'
// weights W. Deterministic: each link end x's parts are stable-sorted by key and summed in
// order (link order, then the walk's order), then the per-x sums of a key are added in x order;
// the GPU (gi_cuda.cu) sums in exactly this order, so both give the same doubles.
struct Blocks {
    size_t n = 0;
    detail::HugeArray<uint64_t> key;
    detail::HugeArray<double> w;
};

struct Part {
    uint64_t key;
    double w;
};

// Where one thread keeps the reduced parts of the nodes it did: chunks of huge pages, each node's
// parts contiguous in one chunk.
class PartArena {
  public:
    Part* take(size_t n) {
        if (n == 0) return nullptr;
        if (n > cap_ - used_) {
            cap_ = std::max(n, kChunk), used_ = 0;
            chunks_.push_back(detail::make_huge_array<Part>(cap_));
        }
        used_ += n;
        return chunks_.back().get() + (used_ - n);
    }

  private:
    static constexpr size_t kChunk = size_t(1) << 20;  // 16 MiB
    std::vector<detail::HugeArray<Part>> chunks_;
    size_t cap_ = 0, used_ = 0;
};

// One link end's parts, reduced by key: the walk fills a buffer kept per thread, the sums go to
// the thread's arena.
std::span<const Part> parts_of_node(const detail::GiTree& tree, float theta, int32_t x,
                                    PartArena& arena) {
    thread_local std::vector<Part> buf;
    buf.clear();
    detail::GiLinkPath path;  // x's links in order: each walk skips the descent it shares with
                              // the one before
    for (uint64_t k = tree.link_offsets[x]; k < tree.link_offsets[x + 1]; ++k) {
        const int32_t y = tree.links[k];
        if (y <= x) continue;
        path.seek(tree, theta, x, y);
        detail::gi_link_blocks(
            tree, theta, x, y,
            [&](uint64_t key, double w) {
                buf.push_back({key, w});
            },
            path.a(), path.b());
    }
    std::stable_sort(buf.begin(), buf.end(),
                     [](const Part& p, const Part& q) { return p.key < q.key; });
    size_t n = 0;  // reduce in place: buf[0, n) holds the sums so far
    for (size_t k = 0; k < buf.size(); ++k)
        if (n > 0 && buf[n - 1].key == buf[k].key)
            buf[n - 1].w += buf[k].w;
        else
            buf[n++] = buf[k];
    Part* out = arena.take(n);
    std::copy_n(buf.begin(), n, out);
    return {out, n};
}

// The per-node sums of every key, added in node order. A bucket sort by the key's first element
// (the parts placed at atomic cursors, in any order), then each bucket sorted by (second element,
// node), which is a total order, so the sums run in node order whatever the threads did.
Blocks merge_node_parts(const std::vector<std::span<const Part>>& per) {
    struct Tagged {
        uint32_t e2;
        int32_t node;
        double w;
    };
    const int32_t N = int32_t(per.size());
    uint32_t max_e1 = 0;
    for (const auto& parts : per)
        for (const Part& p : parts) max_e1 = std::max(max_e1, uint32_t(p.key >> 32));
    const size_t num_buckets = size_t(max_e1) + 1;
    std::unique_ptr<std::atomic<uint64_t>[]> cursor(new std::atomic<uint64_t>[num_buckets]);
    for (size_t e = 0; e < num_buckets; ++e) cursor[e].store(0, std::memory_order_relaxed);
    parallel_for(0, N, [&](int32_t x) {
        for (const Part& p : per[x]) cursor[p.key >> 32].fetch_add(1, std::memory_order_relaxed);
    });
    std::vector<uint64_t> start(num_buckets + 1, 0);
    for (size_t e = 0; e < num_buckets; ++e) {
        start[e + 1] = start[e] + cursor[e].load(std::memory_order_relaxed);
        cursor[e].store(start[e], std::memory_order_relaxed);
    }
    const detail::HugeArray<Tagged> all = detail::make_huge_array<Tagged>(start[num_buckets]);
    parallel_for(0, N, [&](int32_t x) {
        for (const Part& p : per[x]) {
            const uint64_t at = cursor[p.key >> 32].fetch_add(1, std::memory_order_relaxed);
            all[at] = {uint32_t(p.key), x, p.w};
        }
    });
    // Sort each bucket and count its distinct keys; then the sums, each key's in node order.
    std::vector<uint64_t> distinct(num_buckets + 1, 0);
    parallel_for(size_t(0), num_buckets, [&](size_t e) {
        Tagged* const first = all.get() + start[e];
        Tagged* const last = all.get() + start[e + 1];
        std::sort(first, last, [](const Tagged& p, const Tagged& q) {
            return p.e2 != q.e2 ? p.e2 < q.e2 : p.node < q.node;
        });
        uint64_t n = 0;
        for (const Tagged* it = first; it != last; ++it) n += (it == first || it[-1].e2 != it->e2);
        distinct[e + 1] = n;
    });
    for (size_t e = 0; e < num_buckets; ++e) distinct[e + 1] += distinct[e];
    Blocks b;
    b.n = distinct[num_buckets];
    b.key = detail::make_huge_array<uint64_t>(b.n);
    b.w = detail::make_huge_array<double>(b.n);
    parallel_for(size_t(0), num_buckets, [&](size_t e) {
        uint64_t out = distinct[e];
        for (uint64_t k = start[e]; k < start[e + 1]; ++k)
            if (k > start[e] && all[k - 1].e2 == all[k].e2) {
                b.w[out - 1] += all[k].w;
            } else {
                b.key[out] = (uint64_t(e) << 32) | all[k].e2;
                b.w[out++] = all[k].w;
            }
    });
    return b;
}

Blocks cpu_blocks(const detail::GiTree& tree, float theta, const ProgressCallback& progress) {
    const int32_t N = tree.num_nodes;
    std::vector<std::span<const Part>> per(N);
    tbb::enumerable_thread_specific<PartArena> arenas;
    detail::Progress bar("gi refinement", uint64_t(N), &progress);
    std::mutex bar_mutex;
    std::atomic<uint64_t> done{0};
    parallel_for(0, N, [&](int32_t x) {
        const uint64_t finished = ++done;
        if (std::unique_lock lock(bar_mutex, std::try_to_lock); lock) bar.set(finished);
        per[x] = parts_of_node(tree, theta, x, arenas.local());
    });
    bar.finish();
    return merge_node_parts(per);
}

std::string cpu_name() { return "cpu (" + cpu_threads() + ")"; }

}  // namespace

std::vector<NodeGeom> detail::gi_node_geometry(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    std::vector<NodeGeom> g(t.num_nodes());
    parallel_for(0, t.num_nodes(), [&](int32_t n) {
        double a = 0, c[3] = {0, 0, 0}, m[3] = {0, 0, 0};
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k) {
            const double ak = area_of(ps, k);
            const Vec3 p = ps.positions[k], q = ps.normals[k];
            a += ak;
            c[0] += ak * p.x, c[1] += ak * p.y, c[2] += ak * p.z;
            m[0] += ak * q.x, m[1] += ak * q.y, m[2] += ak * q.z;
        }
        NodeGeom& o = g[n];
        o.area = float(a);
        o.point_area = float(a / std::max<uint32_t>(1, t.point_end()[n] - t.point_begin()[n]));
        if (a > 0) {
            o.center = Vec3{float(c[0] / a), float(c[1] / a), float(c[2] / a)};
            o.normal = Vec3{float(m[0] / a), float(m[1] / a), float(m[2] / a)};
        } else {
            o.center = (t.boxes()[n].lo + t.boxes()[n].hi) * 0.5f;
        }
        o.size = 0.5f * length(t.boxes()[n].hi - t.boxes()[n].lo);
    });
    return g;
}

detail::GiTree detail::gi_tree_view(const VisibilityMap& vm, const NodeGeom* geom,
                                    const float* area, const int32_t* point_leaf) {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    return GiTree{t.num_nodes(),
                  uint32_t(ps.size()),
                  t.skip().data(),
                  t.node_leaf().data(),
                  t.parent().data(),
                  t.point_begin().data(),
                  t.point_end().data(),
                  geom,
                  ps.positions.data(),
                  ps.normals.data(),
                  area,
                  point_leaf,
                  vm.link_offsets().data(),
                  vm.link_targets().data()};
}

float gi_kernel(Vec3 pr, Vec3 nr, float ar, Vec3 ps, Vec3 ns, float as) {
    return detail::gi_kernel_hd(pr, nr, ar, ps, ns, as);
}

struct RadiositySolver::Impl {
    const VisibilityMap& vm;
    GiParams params;
    GiStats stats;
    int done = 0;
    // Host arrays behind the views.
    detail::HugeVector<uint64_t> row;  // huge pages, and src, coef filled without a zero fill
    detail::HugeVector<uint32_t> src;
    detail::HugeVector<float> coef;
    std::vector<Vec3> emission, albedo;
    std::vector<float> area, inv_area;
    std::vector<double> node_area;  // for interaction_list()
    std::vector<int32_t> point_leaf;
    std::vector<uint8_t> emits;  // per node: holds an emitting point
    std::vector<Vec3> B, G;
    std::vector<NodeGeom> geom;
    detail::GiTree tree;
    detail::GiView view;
    std::unique_ptr<detail::GiDevice> device;

    explicit Impl(const VisibilityMap& m) : vm(m) {}

    void setup();
    void prepare_arrays();
    void attach_device();
    bool refine_on_device();
    void refine_on_host();
    void check_total(uint64_t total) const;
    void sort_rows();
    void make_view();
    void upload_bounces();
    void cpu_bounce();
    void reset_host();
    detail::GiGatherView gather_view(float theta) const;
};

// Step 1: per-point and per-node arrays, and the tree view the refinement and gather read.
void RadiositySolver::Impl::prepare_arrays() {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    const int32_t N = t.num_nodes();
    const uint32_t P = uint32_t(ps.size());
    geom = detail::gi_node_geometry(vm);
    emission.resize(P), albedo.resize(P), area.resize(P), point_leaf.resize(P);
    parallel_for(uint32_t(0), P, [&](uint32_t i) {
        emission[i] = emission_of(ps, i);
        albedo[i] = albedo_of(ps, i);
        area[i] = area_of(ps, i);
    });
    for (int32_t l = 0; l < t.num_leaves(); ++l) {
        const int32_t n = t.leaf_node()[l];
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k) point_leaf[k] = n;
    }
    inv_area.resize(N), node_area.resize(N), emits.assign(N, 0);
    parallel_for(0, N, [&](int32_t n) {
        inv_area[n] = geom[n].area > 0 ? 1.0f / geom[n].area : 0.0f;
        node_area[n] = geom[n].area;
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n] && !emits[n]; ++k)
            emits[n] = !(emission[k] == Vec3{});
    });
    tree = detail::gi_tree_view(vm, geom.data(), area.data(), point_leaf.data());
}

void RadiositySolver::Impl::check_total(uint64_t total) const {
    if (total > params.max_interactions)
        throw Error(fmt::format(
            "gi: theta {}: the refinement has {} interactions (more than the limit {}); use a "
            "smaller theta",
            params.theta, total, params.max_interactions));
}

// Step 2 (host): the interactions in two passes, counted per receiver, then filled at atomic
// cursors; sort_rows() then orders each row by source.
void RadiositySolver::Impl::refine_on_host() {
    const int32_t N = vm.octree().num_nodes();
    const uint64_t num_el = uint64_t(N) + vm.points().size();
    const bool by_links = params.refine == GiRefine::kLinks;
    Blocks blocks;
    if (!by_links) blocks = cpu_blocks(tree, params.theta, params.progress);
    auto element_area = [&](uint32_t e) {
        return e < uint32_t(N) ? double(geom[e].area) : double(area[e - uint32_t(N)]);
    };
    auto run_refinement = [&](auto&& make_emit) {
        if (by_links) return Refiner{vm, geom, params.theta}.run(make_emit);
        parallel_for_range<size_t>(blocks.n, 4096, [&](size_t chunk_begin, size_t chunk_end) {
            auto emit = make_emit();
            for (size_t k = chunk_begin; k < chunk_end; ++k) {
                const uint32_t e1 = uint32_t(blocks.key[k] >> 32), e2 = uint32_t(blocks.key[k]);
                const double a1 = element_area(e1), a2 = element_area(e2);
                if (!(a1 > 0) || !(a2 > 0)) continue;
                const double kw = blocks.w[k];  // sum of A_x A_y K(x, y) over the visible parts
                emit(e1, e2, float(std::min(1.0, kw / a1)));
                emit(e2, e1, float(std::min(1.0, kw / a2)));
            }
        });
    };
    std::unique_ptr<std::atomic<uint64_t>[]> count(new std::atomic<uint64_t>[num_el + 1]);
    for (uint64_t e = 0; e <= num_el; ++e) count[e].store(0, std::memory_order_relaxed);
    run_refinement([&] {
        return [&](uint32_t r, uint32_t, float, bool = false) {
            count[r].fetch_add(1, std::memory_order_relaxed);
        };
    });
    row.assign(num_el + 1, 0);
    for (uint64_t e = 0; e < num_el; ++e) row[e + 1] = row[e] + count[e].load();
    check_total(row[num_el]);
    for (uint64_t e = 0; e < num_el; ++e) count[e].store(row[e], std::memory_order_relaxed);
    src.resize(row[num_el]), coef.resize(row[num_el]);
    run_refinement([&] {
        return [&](uint32_t r, uint32_t s, float f, bool = false) {
            const uint64_t at = count[r].fetch_add(1, std::memory_order_relaxed);
            src[at] = s;
            coef[at] = f;
        };
    });
    sort_rows();
}

// Rows sorted by source, so the sums run in an order that does not depend on thread timing.
void RadiositySolver::Impl::sort_rows() {
    const uint64_t num_el = row.size() - 1;
    parallel_for(uint64_t(0), num_el, [&](uint64_t e) {
        const uint64_t b = row[e], n = row[e + 1] - b;
        if (n < 2) return;
        std::vector<std::pair<uint32_t, float>> tmp(n);
        for (uint64_t k = 0; k < n; ++k) tmp[k] = {src[b + k], coef[b + k]};
        std::sort(tmp.begin(), tmp.end());
        for (uint64_t k = 0; k < n; ++k) src[b + k] = tmp[k].first, coef[b + k] = tmp[k].second;
    });
}

// Step 2 (GPU): the same blocks and interactions made on the device (gi_cuda.cu), the list also
// copied back here; false (with stats.note) when the device cannot take it.
bool RadiositySolver::Impl::refine_on_device() {
    if (!device || params.refine != GiRefine::kBlocks) return false;
    try {
        device->upload_tree(tree, emits.data());
        device->refine_blocks(
            params.theta, [&](uint64_t total) { check_total(total); }, row, src, coef);
        return true;
    } catch (const Error& e) {
        if (std::string_view(e.what()).starts_with("gi: theta")) throw;
        device.reset();
        stats.note = fmt::format(
            "backend {}: the GPU could not take the refinement ({}); using "
            "the CPU",
            name_of(params.backend), e.what());
        return false;
    }
}

void RadiositySolver::Impl::make_view() {
    const Octree& t = vm.octree();
    const uint64_t num_el = row.size() - 1;
    stats.point_interactions = row[num_el] - row[uint64_t(t.num_nodes())];
    stats.node_interactions = row[num_el] - stats.point_interactions;
    B.assign(num_el, Vec3{});
    G.assign(num_el, Vec3{});
    view = detail::GiView{t.num_nodes(),
                          uint32_t(vm.points().size()),
                          row.data(),
                          src.data(),
                          coef.data(),
                          emission.data(),
                          albedo.data(),
                          area.data(),
                          point_leaf.data(),
                          t.parent().data(),
                          t.point_begin().data(),
                          t.point_end().data(),
                          inv_area.data(),
                          B.data(),
                          G.data()};
    reset_host();
}

void RadiositySolver::Impl::attach_device() {
    if (params.backend == Backend::kCpu) return;
    std::string why;
    device = detail::make_gi_cuda(&why);
    if (!device) detail::fall_back_to_cpu(params.backend, "gi: backend", why, &stats.note);
}

// Step 3: the bounce arrays on the device (the interaction list is there already when the
// device refined).
void RadiositySolver::Impl::upload_bounces() {
    if (!device) return;
    try {
        device->upload_tree(tree, emits.data());
        device->upload(view, row.back());
    } catch (const Error& e) {
        // Too large for the device (or the device failed): the CPU gives the same answers.
        device.reset();
        stats.note =
            fmt::format("backend {}: the GPU could not take the problem ({}); using the CPU",
                        name_of(params.backend), e.what());
    }
}

void RadiositySolver::Impl::setup() {
    const auto t0 = Clock::now();
    prepare_arrays();
    attach_device();
    if (!refine_on_device()) refine_on_host();
    make_view();
    upload_bounces();
    stats.backend = device ? device->name() : cpu_name();
    stats.seconds_setup = seconds_since(t0);
}

detail::GiGatherView RadiositySolver::Impl::gather_view(float theta) const {
    return detail::GiGatherView{tree,          B.data(), emits.data(), emission.data(),
                                albedo.data(), theta};
}

void RadiositySolver::Impl::reset_host() {
    const int32_t N = view.num_nodes;
    parallel_for(uint32_t(0), view.num_points,
                 [&](uint32_t i) { B[uint64_t(N) + i] = emission[i]; });
    parallel_for(0, N, [&](int32_t n) { detail::gi_pull_up(view, n); });
}

void RadiositySolver::Impl::cpu_bounce() {
    const uint64_t num_el = uint64_t(view.num_nodes) + view.num_points;
    parallel_for_range<uint64_t>(num_el, 256, [&](uint64_t chunk_begin, uint64_t chunk_end) {
        for (uint64_t e = chunk_begin; e < chunk_end; ++e) detail::gi_gather(view, e);
    });
    parallel_for_range<uint32_t>(view.num_points, 1024,
                                 [&](uint32_t chunk_begin, uint32_t chunk_end) {
                                     for (uint32_t i = chunk_begin; i < chunk_end; ++i)
                                         detail::gi_point_update(view, i);
                                 });
    parallel_for(0, view.num_nodes, [&](int32_t n) { detail::gi_pull_up(view, n); });
}

void GiParams::check(const std::string& source) const {
    if (!(theta > 0) || !std::isfinite(theta))
        throw Error(
            fmt::format("{}: theta: {} (the separation parameter must be > 0)", source, theta));
    if (bounces < 0) throw Error(fmt::format("{}: bounces: {} (must be >= 0)", source, bounces));
}

RadiositySolver::RadiositySolver(const VisibilityMap& vm, const GiParams& params, GiStats* stats)
    : impl_(std::make_unique<Impl>(vm)) {
    vm.require_links("gi");
    params.check("gi");
    check_points(vm, "gi");
    impl_->params = params;
    impl_->setup();
    if (stats) *stats = impl_->stats;
}

RadiositySolver::~RadiositySolver() = default;

void RadiositySolver::reset() {
    impl_->reset_host();
    if (impl_->device) impl_->device->set_radiosity(impl_->B.data());
    impl_->done = 0;
    impl_->stats.seconds_bounce.clear();
}

void RadiositySolver::bounce() {
    const auto t0 = Clock::now();
    if (impl_->device)
        impl_->device->bounce();
    else
        impl_->cpu_bounce();
    impl_->stats.seconds_bounce.push_back(seconds_since(t0));
    impl_->done++;
}

int RadiositySolver::bounces_done() const { return impl_->done; }

std::vector<Vec3> RadiositySolver::radiosity() const {
    if (impl_->device) impl_->device->download_radiosity(impl_->B.data());
    const auto first = impl_->B.begin() + impl_->view.num_nodes;
    return std::vector<Vec3>(first, first + impl_->view.num_points);
}

const GiStats& RadiositySolver::stats() const { return impl_->stats; }

std::vector<Vec3> RadiositySolver::final_gather(float theta,
                                                std::span<const uint32_t> points) const {
    if (!(theta > 0) || !std::isfinite(theta))
        throw Error(fmt::format("gi: final gather: theta: {} (must be > 0)", theta));
    const uint32_t P = impl_->view.num_points;
    for (uint32_t i : points)
        if (i >= P) throw Error(fmt::format("gi: final gather: point {} of {}", i, P));
    const size_t n = points.empty() ? P : points.size();
    std::vector<Vec3> out(n);
    if (impl_->device) {
        impl_->device->final_gather(theta, points.data(), n, !points.empty(), out.data());
        return out;
    }
    const detail::GiGatherView v = impl_->gather_view(theta);
    // Progress for a gather of every point (the picture's), not for the reference's short lists.
    const ProgressCallback* cb = points.empty() ? &impl_->params.progress : nullptr;
    detail::Progress bar("gi final gather", n, cb && *cb ? cb : nullptr);
    parallel_for_range<size_t>(n, 64, [&](size_t chunk_begin, size_t chunk_end) {
        for (size_t k = chunk_begin; k < chunk_end; ++k)
            out[k] = detail::gi_final_gather_point(v, points.empty() ? uint32_t(k) : points[k]);
        bar.add((chunk_end - chunk_begin));
    });
    bar.finish();
    return out;
}

void RadiositySolver::interaction_list(std::vector<uint64_t>& row, std::vector<uint32_t>& src,
                                       std::vector<float>& coef, std::vector<double>& area) const {
    row.assign(impl_->row.begin(), impl_->row.end());
    src.assign(impl_->src.begin(), impl_->src.end());
    coef.assign(impl_->coef.begin(), impl_->coef.end());
    const int32_t N = impl_->view.num_nodes;
    area.resize(impl_->row.size() - 1);
    for (int32_t n = 0; n < N; ++n) area[n] = impl_->node_area[n];
    for (uint32_t k = 0; k < impl_->view.num_points; ++k) area[N + k] = impl_->area[k];
}

std::vector<Vec3> solve_radiosity(const VisibilityMap& vm, const GiParams& params, GiStats* stats) {
    RadiositySolver s(vm, params);
    for (int b = 0; b < params.bounces; ++b) s.bounce();
    if (stats) *stats = s.stats();
    return s.radiosity();
}

std::vector<Vec3> brute_force_radiosity(const VisibilityMap& vm, int bounces,
                                        std::vector<std::vector<Vec3>>* per_bounce,
                                        std::vector<double>* seconds_per_bounce, uint64_t* pairs) {
    if (bounces < 0) throw Error(fmt::format("gi: bounces: {} (must be >= 0)", bounces));
    check_points(vm, "gi");
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    const uint32_t P = uint32_t(ps.size());
    std::vector<Vec3> B(P), next(P);
    for (uint32_t i = 0; i < P; ++i) B[i] = emission_of(ps, i);
    if (pairs) {
        *pairs = parallel_reduce_range<uint32_t>(
            P, 1, uint64_t(0),
            [&](uint32_t chunk_begin, uint32_t chunk_end, uint64_t acc) {
                for (uint32_t i = chunk_begin; i < chunk_end; ++i)
                    for (int32_t A = t.leaf_node()[t.leaf_of_point(i)]; A >= 0; A = t.parent()[A])
                        for (int32_t L : vm.links(A)) acc += t.point_end()[L] - t.point_begin()[L];
                return acc;
            },
            std::plus<>());
    }
    for (int b = 0; b < bounces; ++b) {
        const auto t0 = Clock::now();
        parallel_for_range<uint32_t>(P, 64, [&](uint32_t chunk_begin, uint32_t chunk_end) {
            for (uint32_t i = chunk_begin; i < chunk_end; ++i) {
                const Vec3 pi = ps.positions[i], ni = ps.normals[i];
                const float ai = area_of(ps, i);
                Vec3 h{0, 0, 0};
                for (int32_t A = t.leaf_node()[t.leaf_of_point(i)]; A >= 0; A = t.parent()[A])
                    for (int32_t L : vm.links(A))
                        for (uint32_t j = t.point_begin()[L]; j < t.point_end()[L]; ++j) {
                            const float aj = area_of(ps, j);
                            const float k =
                                gi_kernel(pi, ni, ai, ps.positions[j], ps.normals[j], aj);
                            if (k > 0) h = h + B[j] * (k * aj);
                        }
                const Vec3 E = emission_of(ps, i), rho = albedo_of(ps, i);
                next[i] = Vec3{E.x + rho.x * h.x, E.y + rho.y * h.y, E.z + rho.z * h.z};
            }
        });
        B.swap(next);
        if (seconds_per_bounce) seconds_per_bounce->push_back(seconds_since(t0));
        if (per_bounce) per_bounce->push_back(B);
    }
    return B;
}

Vec3 total_power(const VisibilityMap& vm, const std::vector<Vec3>& radiosity) {
    double s[3] = {0, 0, 0};
    for (size_t i = 0; i < radiosity.size() && i < vm.points().size(); ++i) {
        const double a = area_of(vm.points(), i);
        s[0] += a * radiosity[i].x, s[1] += a * radiosity[i].y, s[2] += a * radiosity[i].z;
    }
    const double unit2 = vm.octree().scale() * vm.octree().scale();  // areas back in input units
    return Vec3{float(s[0] * unit2), float(s[1] * unit2), float(s[2] * unit2)};
}

double relative_rms(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    if (a.size() != b.size())
        throw Error(fmt::format("relative_rms: {} values against {}", a.size(), b.size()));
    double num = 0, den = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        const Vec3 d = a[i] - b[i];
        num += double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z;
        den += double(b[i].x) * b[i].x + double(b[i].y) * b[i].y + double(b[i].z) * b[i].z;
    }
    return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

float tone_map(const VisibilityMap& vm, const std::vector<Vec3>& radiosity, float exposure,
               std::vector<Vec3>& colors) {
    if (!std::isfinite(exposure)) throw Error(fmt::format("gi: exposure: {}", exposure));
    const PointSet& ps = vm.points();
    if (!(exposure > 0)) {
        std::vector<float> lum;
        for (size_t i = 0; i < radiosity.size(); ++i) {
            const Vec3 E = emission_of(ps, i);
            if (E.x > 0 || E.y > 0 || E.z > 0) continue;
            const Vec3 b = radiosity[i];
            lum.push_back(std::max({b.x, b.y, b.z}));
        }
        float ref = 0;
        if (!lum.empty()) {
            const size_t k = std::min(lum.size() - 1, size_t(0.95 * double(lum.size())));
            std::nth_element(lum.begin(), lum.begin() + k, lum.end());
            ref = lum[k];
        }
        exposure = ref > 0 ? 0.8f / ref : 1.0f;
    }
    colors.resize(radiosity.size());
    auto ch = [&](float v) { return std::clamp(v * exposure, 0.0f, 1.0f); };
    for (size_t i = 0; i < radiosity.size(); ++i)
        colors[i] = Vec3{ch(radiosity[i].x), ch(radiosity[i].y), ch(radiosity[i].z)};
    return exposure;
}

#ifndef VMAP_HAVE_CUDA
namespace detail {
std::unique_ptr<GiDevice> make_gi_cuda(std::string* why) {
    if (why) *why = "this vmap was built without CUDA (nvcc was not found at build time)";
    return nullptr;
}
}  // namespace detail
#endif

}  // namespace vmap
