// V-map construction (paper §3 and §4.3; docs/design.md).
//
// Every unordered leaf pair (a, b) lies in exactly one "sibling rectangle": leaves(A) x leaves(B)
// for the two distinct children A, B of the lowest common ancestor of a and b. Since leaves are in
// depth-first order, each such rectangle is contiguous in the leaf-by-leaf matrix. The builder
// resolves those sibling pairs through the bounded frontier of vmap/frontier.h: level by level
// it decides node pairs whole where the bounds of visibility/node_pair.h prove all or none of
// their leaf pairs visible (construction "nodes"; "leaf-pairs" decides nothing, the oracle),
// splits the undecided ones into child pairs, and hands the rest as rectangles to a backend,
// which evaluates them in batches into bit-packed tables (the paper's LVS); links are extracted
// from each table on the host while the backend works on the next batch. The steps of a build:
// check the parameters, build the octree (octree_step), pick the backend and the node tests,
// resolve the frontier (frontier_step), and fill the link arrays (links_step).
#include <fmt/format.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <memory>

#include "visibility/backend.h"
#include "visibility/grid_walk.h"
#include "visibility/node_pair.h"
#include "vmap/build_checks.h"
#include "vmap/build_parts.h"
#include "vmap/error.h"
#include "vmap/frontier.h"
#include "vmap/map_access.h"
#include "octree/records.h"
#include "util/device.h"

namespace vmap {
namespace {

using Clock = std::chrono::steady_clock;


std::unique_ptr<detail::Backend> pick_backend(const BuildParams& params, std::string* note,
                                              const std::string& source) {
    (void)source;  // BuildParams::check refused the grid walk with backend cuda
    if (params.occluders != OccluderSearch::kGridWalk)
        return detail::make_backend(params.backend, note, params.device);
    return detail::make_grid_walk_backend();
}

// The sibling pairs: every unordered pair of distinct children of every internal node.
std::vector<detail::NodePairRef> sibling_pairs(const Octree& t) {
    std::vector<detail::NodePairRef> roots;
    for (int32_t n = 0; n < t.num_nodes(); ++n) {
        if (t.is_leaf(n)) continue;
        std::vector<int32_t> ch;
        t.for_each_child(n, [&](int32_t c) { ch.push_back(c); });
        for (size_t i = 0; i < ch.size(); ++i)
            for (size_t j = i + 1; j < ch.size(); ++j) roots.push_back({ch[i], ch[j]});
    }
    return roots;
}

// The node pairs a caller gives (BuildParams::top_pairs: the MPI build's share, in chunks) as
// frontier roots, list after list until it gives none.
std::function<std::vector<detail::NodePairRef>()> given_pairs(const BuildParams& params,
                                                              const Octree& t) {
    return [&params, &t] {
        std::vector<detail::NodePairRef> roots;
        for (const auto& [a, b] : params.top_pairs(t)) roots.push_back({a, b});
        return roots;
    };
}

// Node bounds and the context of the node tests, when the construction decides node pairs.
struct NodeTests {
    bool on = false;
    detail::NodeBoundsSet nb;
    detail::NodePairContext ctx;
};
void prepare_node_tests(const Octree& t, const BuildParams& params, NodeTests& nt) {
    // Node-level decisions are proofs about the box walk of leaf_pair.h, not the grid walk.
    // auto: nodes on both backends (on the GPU with lanes: docs/results.md "Construction lanes").
    const bool nodes = params.construction != Construction::kLeafPairs;
    nt.on = nodes && params.occluders == OccluderSearch::kBoxes;
    if (!nt.on) return;
    nt.nb = detail::node_bounds(t);
    nt.ctx = {octree_view(t),
              nt.nb.nodes.data(),
              nt.nb.cones.data(),
              t.skip().data(),
              in_octree_frame(params.visibility, t.scale()),
              detail::node_pair_margin(t.boxes()[0])};
    nt.ctx.leaves_stored = true;  // node_bounds() stores the leaves' bounds too
}

// Points to octree (in the unit frame), with the point order and its inverse.
VisibilityMap octree_step(PointSet points, const BuildParams& params, BuildStats& st,
                          const std::string& source) {
    const auto t0 = Clock::now();
    detail::prepare_points(points, st, source);
    VisibilityMap vm;
    detail::MapData& d = detail::MapAccess::data(vm);
    d.octree_params = params.octree;
    d.visibility_params = params.visibility;
    d.octree = Octree::build_in_unit_frame(points, params.octree, d.order, source);
    d.points = std::move(points);
    detail::set_inverse(d);
    st.seconds_octree = seconds_since(t0);
    return vm;
}

// The sizes of the frontier: jobs and batches bounded by max_batch_pairs, walks by walk_pairs
// (the backend's choice when 0: 4096 on the CPU; 2048 on the GPU, measured with three lanes
// against 256 to 8192 in docs/results.md).
detail::FrontierParams frontier_params(const BuildParams& params, bool gpu, bool nodes) {
    detail::FrontierParams fp;
    fp.max_job_pairs = std::max<uint64_t>(1, params.max_batch_pairs / 16);
    fp.walk_pairs = params.walk_pairs ? params.walk_pairs : (gpu ? 2048 : 4096);
    fp.max_level_pairs = size_t(params.max_level_pairs);
    // Words per batch (a batch's rows are padded to 32 bits); a job with more words than this
    // makes a batch of its own, and the backend's buffers grow to fit it. The node path's
    // batches hold one level slice's walks (jobs of at most walk_pairs leaf pairs): a quarter
    // of the words serves them (8 MB a buffer by default), which keeps the device memory of a
    // large scene in bounds (the node bounds take their share there).
    fp.batch_words = (nodes ? params.max_batch_pairs / 4 : params.max_batch_pairs) / 32 + 1;
    return fp;
}

// Every leaf pair resolved, decided at node level or walked on the backend, into links.
std::unique_ptr<detail::Frontier> frontier_step(const Octree& t, const BuildParams& params,
                                                const std::string& source, BuildStats& st,
                                                NodeTests& nt) {
    const auto t1 = Clock::now();
    std::string note;
    std::unique_ptr<detail::Backend> backend = pick_backend(params, &note, source);
    st.backend = backend->name();
    st.note = note;
    const bool gpu = st.backend.rfind("cuda", 0) == 0;
    prepare_node_tests(t, params, nt);
    st.construction = nt.on ? "nodes" : "leaf-pairs";
    const detail::FrontierParams fp = frontier_params(params, gpu, nt.on);
    backend->prepare(t, in_octree_frame(params.visibility, t.scale()), fp.batch_words);
    backend->set_node_context(nt.on ? &nt.ctx : nullptr);
    st.seconds_plan = seconds_since(t1);
    auto fr = std::make_unique<detail::Frontier>(t, nt.on ? &nt.ctx : nullptr, *backend, params,
                                                 fp, st);
    if (params.top_pairs) {
        fr->run(given_pairs(params, t));
    } else {
        const int lanes = params.lanes > 0 ? params.lanes : (gpu ? 3 : 1);
        std::vector<std::unique_ptr<detail::Backend>> more;
        for (int k = 1; k < lanes; ++k)
            if (std::unique_ptr<detail::Backend> b = backend->lane()) more.push_back(std::move(b));
        fr->add_lanes(std::move(more));
        fr->run(sibling_pairs(t));
    }
    st.lanes = uint32_t(fr->lanes());
    st.seconds_plan += st.seconds_decide;  // "plan and node tests"
    st.peak_device_bytes = backend->peak_device_bytes();
    st.seconds_backend = backend->busy_seconds();
    return fr;
}

// The per-node link arrays from every link made (or only their number).
void links_step(VisibilityMap& vm, detail::Frontier& fr, const BuildParams& params,
                BuildStats& st, std::vector<detail::Link>* raw) {
    const auto tl = Clock::now();
    if (params.keep_links && raw) {  // the links as made, no arrays (build_parts.h)
        for (const auto& p : fr.pieces) raw->insert(raw->end(), p.begin(), p.end());
        detail::MapAccess::data(vm).link_offsets.clear();
        st.links = raw->size();
    } else if (params.keep_links) {
        std::vector<std::span<const detail::Link>> spans;
        for (const auto& p : fr.pieces) spans.emplace_back(p);
        fr.arrays.finish(vm, spans);
        st.links = vm.num_links();
    } else {
        detail::MapAccess::data(vm).link_offsets.clear();  // has_links() is false: queries and save refuse the map
        st.links = fr.counted_links;
    }
    st.seconds_links = seconds_since(tl);
}

// The construction over the points and octree of vm (octree_step's), from t0 (the build's start).
// check_normals: the normals' consistency check runs beside the construction (the points stay
// in vm, unchanged, until it is done).
VisibilityMap links_in_arena(VisibilityMap vm, const BuildParams& params, BuildStats& st,
                             const std::string& source, Clock::time_point t0, bool check_normals,
                             std::vector<detail::Link>* raw = nullptr) {
    const auto t1 = Clock::now();
    detail::NormalsCheck check;
    if (check_normals) check.start(vm.points());
    NodeTests nt;
    std::unique_ptr<detail::Frontier> fr = frontier_step(vm.octree(), params, source, st, nt);
    links_step(vm, *fr, params, st, raw);
    check.finish(st);
    st.seconds_visibility = seconds_since(t1);
    st.seconds_total = seconds_since(t0);
    // (A share of the pairs cannot judge the whole.)
    if (!params.top_pairs) detail::check_facing(st, vm.octree(), params.visibility);
    return vm;
}

// f() in an arena of params.threads threads (0: the caller's).
template <class F>
auto in_arena(const BuildParams& params, F&& f) {
    if (params.threads == 0) return f();
    tbb::task_arena arena(params.threads);
    return arena.execute(f);
}

}  // namespace

void warm_up_gpu(const BuildParams& params) noexcept {
    if (params.backend == Backend::kCpu || params.occluders == OccluderSearch::kGridWalk) return;
    detail::warm_cuda(params.device);
}

VisibilityMap build_vmap(PointSet points, const BuildParams& params, BuildStats* stats,
                         const std::string& source) {
    params.check(source);
    return in_arena(params, [&] {
        const auto t0 = Clock::now();
        BuildStats st;
        VisibilityMap vm = octree_step(std::move(points), params, st, source);
        vm = links_in_arena(std::move(vm), params, st, source, t0, true);
        if (stats) *stats = std::move(st);
        return vm;
    });
}

namespace detail {

VisibilityMap build_octree(PointSet points, const BuildParams& params, BuildStats& stats,
                           const std::string& source) {
    params.check(source);
    return in_arena(params, [&] {
        VisibilityMap vm = octree_step(std::move(points), params, stats, source);
        detail::NormalsCheck check;
        check.start(vm.points());
        check.finish(stats);
        return vm;
    });
}

VisibilityMap build_links(VisibilityMap base, const BuildParams& params, BuildStats* stats,
                          const std::string& source, std::vector<Link>* raw) {
    params.check(source);
    return in_arena(params, [&] {
        BuildStats st;
        VisibilityMap vm =
            links_in_arena(std::move(base), params, st, source, Clock::now(), false, raw);
        if (stats) *stats = std::move(st);
        return vm;
    });
}

}  // namespace detail
}  // namespace vmap
