// Hierarchical radiosity over the V-map (paper §6.3; the contract is in include/vmap/gi.h).
#include "vmap/gi.h"

#include <fmt/format.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <numbers>

#include "gi/gi_device.h"
#include "util/device.h"
#include "gi/gi_kernels.h"
#include "util/progress.h"
#include "vmap/error.h"

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
    if (vm.octree().num_nodes() == 0 || vm.link_offsets().size() != size_t(vm.octree().num_nodes()) + 1)
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

// What refinement needs of a node: total area, area-weighted mean position and normal, and the
// half-diagonal of its content box.
struct NodeGeom {
    Vec3 center, normal;
    float area = 0, size = 0;
    float point_area = 0;  // mean area of its points
};

std::vector<NodeGeom> node_geometry(const VisibilityMap& vm) {
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    std::vector<NodeGeom> g(t.num_nodes());
    tbb::parallel_for(0, t.num_nodes(), [&](int32_t n) {
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

// Refines every V-map link into receiver/source interactions; calls emit(recv, src, F) for
// each (both directions). Elements: nodes, then points at num_nodes + k.
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
        tbb::parallel_for(tbb::blocked_range<int32_t>(0, vm.octree().num_nodes()), [&](auto r) {
            auto emit = make_emit();
            for (int32_t a = r.begin(); a < r.end(); ++a)
                for (int32_t b : vm.links(a))
                    if (b > a) refine(a, b, emit);
        });
    }
};

// Refinement by blocks (the default): every V-map link (x, y) is split along the partition of
// the leaf-pair matrix that top-down refinement from (root, root) gives: a node pair (A, B)
// (disjoint subtrees) is a block when well separated; otherwise the larger node is opened; two
// leaves that are not well separated exchange point to point. A link reaches its blocks by
// descending from (root, root) towards x and y (and over all children once inside them). Each
// block accumulates W = the area products of the leaf pairs the links make visible in it, so a
// block moves energy only between parts that see each other: receiver A gathers
// K(A, B) W / A_A * B_B from B (fully visible blocks: K A_B B_B, as before). The blocks do not
// grow with the number of links: the per-bounce work is that of classic hierarchical
// radiosity, the visibility of a block is averaged over its parts (shadow edges blur at the
// scale of the nodes, which theta keeps small against their distance).
struct BlockRefiner {
    const VisibilityMap& vm;
    const std::vector<NodeGeom>& g;
    float theta;

    struct Entry {
        uint64_t key;  // (element e1 << 32) | element e2, e1 < e2
        double w;
    };

    bool within(int32_t a, int32_t x) const { return x <= a && a < vm.octree().skip()[x]; }
    bool separated(int32_t a, int32_t b) const {
        if (within(a, b) || within(b, a)) return false;
        if (!flat(a) || !flat(b)) return false;
        return length(g[b].center - g[a].center) > theta * (g[a].size + g[b].size);
    }
    // A block spreads what its receiver gathers evenly over the receiver's area, which is right
    // only for nearly flat content: a curved node (the bunny's ear) would give its points facing
    // away the light of those facing the source. Internal nodes whose mean normal is shorter
    // than 1 - kFlatness / theta (normals spread) are opened instead (leaves are taken as they
    // are: opening them would pair single points with everything they see).
    bool flat(int32_t a) const {
        return vm.octree().is_leaf(a) || length(g[a].normal) >= 1.0f - kFlatness / theta;
    }
    static constexpr float kFlatness = 0.05f;
    int32_t child_toward(int32_t a, int32_t x) const {
        int32_t hit = -1;
        vm.octree().for_each_child(a, [&](int32_t c) {
            if (within(x, c)) hit = c;
        });
        return hit;
    }
    static uint64_t key(uint32_t e1, uint32_t e2) {
        if (e1 > e2) std::swap(e1, e2);
        return (uint64_t(e1) << 32) | e2;
    }

    void descend(int32_t a, int32_t b, int32_t x, int32_t y, std::vector<Entry>& out) const {
        const Octree& t = vm.octree();
        const bool ax = within(a, x), by = within(b, y);
        if (separated(a, b)) {
            // The part of the link inside the block: the finer of the two nodes on each side.
            const NodeGeom& pa = g[ax ? a : x];
            const NodeGeom& pb = g[by ? b : y];
            const float k =
                gi_kernel(pa.center, pa.normal, pa.point_area, pb.center, pb.normal, pb.point_area);
            if (k > 0)
                out.push_back({key(uint32_t(a), uint32_t(b)), double(pa.area) * pb.area * k});
            return;
        }
        const bool la = t.is_leaf(a), lb = t.is_leaf(b);
        if (la && lb) {  // both are inside their link ends: every point pair is visible
            const uint32_t base = uint32_t(t.num_nodes());
            for_point_pairs(vm, a, b, [&](uint32_t i, uint32_t j, float ai, float aj, float k) {
                out.push_back({key(base + i, base + j), double(ai) * aj * k});
            });
            return;
        }
        // Open the node that is not flat enough if only one is, else the larger one.
        const bool fa = flat(a), fb = flat(b);
        const bool open_a = lb || (!la && (fa == fb ? g[a].size >= g[b].size : !fa));
        if (open_a) {
            if (ax)
                t.for_each_child(a, [&](int32_t c) { descend(c, b, x, y, out); });
            else
                descend(child_toward(a, x), b, x, y, out);
        } else {
            if (by)
                t.for_each_child(b, [&](int32_t c) { descend(a, c, x, y, out); });
            else
                descend(a, child_toward(b, y), x, y, out);
        }
    }

    // The blocks with their visible area products, sorted by key. Deterministic: each link
    // end's entries are reduced in link order, then all are sorted by (key, node) and summed
    // in that order.
    std::vector<Entry> run(const ProgressCallback& progress) const {
        const int32_t N = vm.octree().num_nodes();
        std::vector<std::vector<Entry>> per(N);
        detail::Progress bar("gi refinement", uint64_t(N), &progress);
        std::mutex bar_mutex;
        std::atomic<uint64_t> done{0};
        tbb::parallel_for(0, N, [&](int32_t x) {
            const uint64_t finished = ++done;
            if (std::unique_lock lock(bar_mutex, std::try_to_lock); lock) bar.set(finished);
            std::vector<Entry> out;
            for (int32_t y : vm.links(x))
                if (y > x) descend(0, 0, x, y, out);
            std::stable_sort(out.begin(), out.end(),
                             [](const Entry& p, const Entry& q) { return p.key < q.key; });
            std::vector<Entry>& r = per[x];
            for (const Entry& e : out)
                if (!r.empty() && r.back().key == e.key)
                    r.back().w += e.w;
                else
                    r.push_back(e);
        });
        struct Tagged {
            uint64_t key;
            int32_t node;
            double w;
        };
        std::vector<uint64_t> first(size_t(N) + 1, 0);
        for (int32_t x = 0; x < N; ++x) first[x + 1] = first[x] + per[x].size();
        std::vector<Tagged> all(first[N]);
        tbb::parallel_for(0, N, [&](int32_t x) {
            for (size_t k = 0; k < per[x].size(); ++k)
                all[first[x] + k] = {per[x][k].key, x, per[x][k].w};
            std::vector<Entry>().swap(per[x]);
        });
        tbb::parallel_sort(all.begin(), all.end(), [](const Tagged& p, const Tagged& q) {
            return p.key != q.key ? p.key < q.key : p.node < q.node;
        });
        std::vector<Entry> blocks;
        for (const Tagged& e : all)
            if (!blocks.empty() && blocks.back().key == e.key)
                blocks.back().w += e.w;
            else
                blocks.push_back({e.key, e.w});
        return blocks;
    }
};

// The final gather (per point, from the hierarchical solution): point i gathers from every node
// the V-map links to its leaf or an ancestor (all of it sees all of that node), at node level
// (the node's area-weighted mean radiosity, its summed area and mean normal, seen from the
// point itself; a leaf of several points too) when the node is flat and more than theta times its
// size away from the point, else from its children, down to point to point. The receiver is always
// the point, so no block of receivers shares one value: the picture has no block grid, and each
// point's visibility is that of its leaf's links.
struct FinalGather {
    const VisibilityMap& vm;
    const std::vector<NodeGeom>& g;
    const std::vector<uint8_t>& emits;  // per node: holds an emitting point
    const Vec3* B;                      // per element: nodes then points
    float theta;

    Vec3 from_node(Vec3 x, Vec3 n, float a, int32_t L) const {
        const Octree& t = vm.octree();
        const NodeGeom& gl = g[L];
        const bool leaf = t.is_leaf(L);
        // Emitters are always gathered point by point: the direct light carries the shadows and
        // most of the power, and the lights are a small share of the points.
        const bool many = t.point_end()[L] - t.point_begin()[L] > 1;
        if (many && !emits[L] && length(gl.normal) >= 1.0f - BlockRefiner::kFlatness / theta &&
            length(gl.center - x) > theta * gl.size) {
            const float k = gi_kernel(x, n, a, gl.center, gl.normal, gl.point_area);
            return k > 0 ? B[L] * (k * gl.area) : Vec3{};
        }
        Vec3 h{0, 0, 0};
        if (leaf) {
            const PointSet& ps = vm.points();
            const uint64_t base = uint64_t(t.num_nodes());
            for (uint32_t j = t.point_begin()[L]; j < t.point_end()[L]; ++j) {
                const float aj = area_of(ps, j);
                const float k = gi_kernel(x, n, a, ps.positions[j], ps.normals[j], aj);
                if (k > 0) h = h + B[base + j] * (k * aj);
            }
            return h;
        }
        t.for_each_child(L, [&](int32_t c) { h = h + from_node(x, n, a, c); });
        return h;
    }

    Vec3 at(uint32_t i) const {
        const Octree& t = vm.octree();
        const PointSet& ps = vm.points();
        const Vec3 x = ps.positions[i], n = ps.normals[i];
        const float a = area_of(ps, i);
        Vec3 h{0, 0, 0};
        for (int32_t A = t.leaf_node()[t.leaf_of_point(i)]; A >= 0; A = t.parent()[A])
            for (int32_t L : vm.links(A)) h = h + from_node(x, n, a, L);
        const Vec3 E = emission_of(ps, i), rho = albedo_of(ps, i);
        return Vec3{E.x + rho.x * h.x, E.y + rho.y * h.y, E.z + rho.z * h.z};
    }
};

std::string cpu_name() {
    return fmt::format("cpu ({} threads)", tbb::this_task_arena::max_concurrency());
}

}  // namespace

float gi_kernel(Vec3 pr, Vec3 nr, float ar, Vec3 ps, Vec3 ns, float as) {
    const Vec3 d = ps - pr;
    const float d2 = dot(d, d);
    if (!(d2 > 0)) return 0;
    const float len = std::sqrt(d2);
    // dot(ns, -d) is exactly -dot(ns, d): K(r, s) and K(s, r) are the same float.
    const float cr = dot(nr, d) / len;
    const float cs = -dot(ns, d) / len;
    if (!(cr > 0) || !(cs > 0)) return 0;
    return (cr * cs) / (kPi * d2 + std::max(ar, as));
}

struct RadiositySolver::Impl {
    const VisibilityMap& vm;
    GiParams params;
    GiStats stats;
    int done = 0;
    // Host arrays behind the view.
    std::vector<uint64_t> row;
    std::vector<uint32_t> src;
    std::vector<float> coef;
    std::vector<Vec3> emission, albedo;
    std::vector<float> area, inv_area;
    std::vector<double> node_area;  // for interaction_list()
    std::vector<int32_t> point_leaf;
    std::vector<Vec3> B, G;
    std::vector<NodeGeom> geom;
    detail::GiView view;
    std::unique_ptr<detail::GiDevice> device;

    explicit Impl(const VisibilityMap& m) : vm(m) {}

    void setup();
    void cpu_bounce();
    void reset_host();
};

void RadiositySolver::Impl::setup() {
    const auto t0 = Clock::now();
    const Octree& t = vm.octree();
    const PointSet& ps = vm.points();
    const int32_t N = t.num_nodes();
    const uint32_t P = uint32_t(ps.size());
    const uint64_t num_el = uint64_t(N) + P;

    geom = node_geometry(vm);
    emission.resize(P), albedo.resize(P), area.resize(P), point_leaf.resize(P);
    tbb::parallel_for(uint32_t(0), P, [&](uint32_t i) {
        emission[i] = emission_of(ps, i);
        albedo[i] = albedo_of(ps, i);
        area[i] = area_of(ps, i);
    });
    for (int32_t l = 0; l < t.num_leaves(); ++l) {
        const int32_t n = t.leaf_node()[l];
        for (uint32_t k = t.point_begin()[n]; k < t.point_end()[n]; ++k) point_leaf[k] = n;
    }
    inv_area.resize(N);
    node_area.resize(N);
    for (int32_t n = 0; n < N; ++n) {
        inv_area[n] = geom[n].area > 0 ? 1.0f / geom[n].area : 0.0f;
        node_area[n] = geom[n].area;
    }

    // Refinement in two passes: count per receiver, then fill at atomic cursors; rows are then
    // sorted by source so the sums run in an order that does not depend on thread timing.
    const Refiner ref{vm, geom, params.theta};
    std::vector<BlockRefiner::Entry> blocks;
    const bool by_links = params.refine == GiRefine::kLinks;
    if (!by_links) blocks = BlockRefiner{vm, geom, params.theta}.run(params.progress);
    auto element_area = [&](uint32_t e) {
        return e < uint32_t(N) ? double(geom[e].area) : double(area_of(ps, e - uint32_t(N)));
    };
    auto run_refinement = [&](auto&& make_emit) {
        if (by_links) return ref.run(make_emit);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, blocks.size(), 4096), [&](auto r) {
            auto emit = make_emit();
            for (size_t k = r.begin(); k < r.end(); ++k) {
                const uint32_t e1 = uint32_t(blocks[k].key >> 32), e2 = uint32_t(blocks[k].key);
                const double a1 = element_area(e1), a2 = element_area(e2);
                if (!(a1 > 0) || !(a2 > 0)) continue;
                const double kw = blocks[k].w;  // sum of A_x A_y K(x, y) over the visible parts
                const bool pt = e1 >= uint32_t(N);
                emit(e1, e2, float(std::min(1.0, kw / a1)), pt);
                emit(e2, e1, float(std::min(1.0, kw / a2)), pt);
            }
        });
    };
    std::unique_ptr<std::atomic<uint64_t>[]> count(new std::atomic<uint64_t>[num_el + 1]);
    for (uint64_t e = 0; e <= num_el; ++e) count[e].store(0, std::memory_order_relaxed);
    std::atomic<uint64_t> n_node{0}, n_point{0};
    run_refinement([&] {
        return [&](uint32_t r, uint32_t, float, bool pt) {
            count[r].fetch_add(1, std::memory_order_relaxed);
            (pt ? n_point : n_node).fetch_add(1, std::memory_order_relaxed);
        };
    });
    stats.node_interactions = n_node.load();
    stats.point_interactions = n_point.load();
    const uint64_t total = stats.interactions();
    if (total > params.max_interactions)
        throw Error(fmt::format(
            "gi: theta {}: the refinement has {} interactions (more than the limit {}); use a "
            "smaller theta",
            params.theta, total, params.max_interactions));
    row.assign(num_el + 1, 0);
    for (uint64_t e = 0; e < num_el; ++e) row[e + 1] = row[e] + count[e].load();
    for (uint64_t e = 0; e < num_el; ++e) count[e].store(row[e], std::memory_order_relaxed);
    src.resize(total), coef.resize(total);
    run_refinement([&] {
        return [&](uint32_t r, uint32_t s, float f, bool) {
            const uint64_t at = count[r].fetch_add(1, std::memory_order_relaxed);
            src[at] = s;
            coef[at] = f;
        };
    });
    count.reset();
    std::vector<BlockRefiner::Entry>().swap(blocks);
    tbb::parallel_for(uint64_t(0), num_el, [&](uint64_t e) {
        const uint64_t b = row[e], n = row[e + 1] - b;
        if (n < 2) return;
        std::vector<std::pair<uint32_t, float>> tmp(n);
        for (uint64_t k = 0; k < n; ++k) tmp[k] = {src[b + k], coef[b + k]};
        std::sort(tmp.begin(), tmp.end());
        for (uint64_t k = 0; k < n; ++k) src[b + k] = tmp[k].first, coef[b + k] = tmp[k].second;
    });

    B.assign(num_el, Vec3{});
    G.assign(num_el, Vec3{});
    view.num_nodes = N;
    view.num_points = P;
    view.row = row.data();
    view.src = src.data();
    view.coef = coef.data();
    view.emission = emission.data();
    view.albedo = albedo.data();
    view.area = area.data();
    view.point_leaf = point_leaf.data();
    view.parent = t.parent().data();
    view.point_begin = t.point_begin().data();
    view.point_end = t.point_end().data();
    view.inv_area = inv_area.data();
    view.B = B.data();
    view.G = G.data();
    reset_host();

    if (params.backend != Backend::kCpu) {
        std::string why;
        device = detail::make_gi_cuda(&why);
        if (!device) detail::fall_back_to_cpu(params.backend, "gi: backend", why, &stats.note);
    }
    if (device) {
        try {
            device->upload(view, total);
        } catch (const Error& e) {
            // Too large for the device (or the device failed): the CPU gives the same answers.
            device.reset();
            stats.note = fmt::format(
                "backend {}: the GPU could not take the problem ({}); "
                "using the CPU",
                name_of(params.backend), e.what());
        }
    }
    if (device) {
        stats.backend = device->name();
    } else {
        stats.backend = cpu_name();
    }
    stats.seconds_setup = seconds_since(t0);
}

void RadiositySolver::Impl::reset_host() {
    const int32_t N = view.num_nodes;
    tbb::parallel_for(uint32_t(0), view.num_points,
                      [&](uint32_t i) { B[uint64_t(N) + i] = emission[i]; });
    tbb::parallel_for(0, N, [&](int32_t n) { detail::gi_pull_up(view, n); });
}

void RadiositySolver::Impl::cpu_bounce() {
    const uint64_t num_el = uint64_t(view.num_nodes) + view.num_points;
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, num_el, 256), [&](auto r) {
        for (uint64_t e = r.begin(); e < r.end(); ++e) detail::gi_gather(view, e);
    });
    tbb::parallel_for(tbb::blocked_range<uint32_t>(0, view.num_points, 1024), [&](auto r) {
        for (uint32_t i = r.begin(); i < r.end(); ++i) detail::gi_point_update(view, i);
    });
    tbb::parallel_for(0, view.num_nodes, [&](int32_t n) { detail::gi_pull_up(view, n); });
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
    if (impl_->device) impl_->device->download_radiosity(impl_->B.data());
    const Impl& m = *impl_;
    std::vector<uint8_t> emits(m.view.num_nodes, 0);
    tbb::parallel_for(0, m.view.num_nodes, [&](int32_t n) {
        for (uint32_t k = m.view.point_begin[n]; k < m.view.point_end[n] && !emits[n]; ++k)
            emits[n] = !(m.emission[k] == Vec3{});
    });
    const FinalGather fg{m.vm, m.geom, emits, m.B.data(), theta};
    const uint32_t P = impl_->view.num_points;
    for (uint32_t i : points)
        if (i >= P) throw Error(fmt::format("gi: final gather: point {} of {}", i, P));
    const size_t n = points.empty() ? P : points.size();
    std::vector<Vec3> out(n);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](auto r) {
        for (size_t k = r.begin(); k < r.end(); ++k)
            out[k] = fg.at(points.empty() ? uint32_t(k) : points[k]);
    });
    return out;
}

void RadiositySolver::interaction_list(std::vector<uint64_t>& row, std::vector<uint32_t>& src,
                                       std::vector<float>& coef, std::vector<double>& area) const {
    row = impl_->row, src = impl_->src, coef = impl_->coef;
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
        *pairs = tbb::parallel_reduce(
            tbb::blocked_range<uint32_t>(0, P), uint64_t(0),
            [&](auto r, uint64_t acc) {
                for (uint32_t i = r.begin(); i < r.end(); ++i)
                    for (int32_t A = t.leaf_node()[t.leaf_of_point(i)]; A >= 0; A = t.parent()[A])
                        for (int32_t L : vm.links(A)) acc += t.point_end()[L] - t.point_begin()[L];
                return acc;
            },
            std::plus<>());
    }
    for (int b = 0; b < bounces; ++b) {
        const auto t0 = Clock::now();
        tbb::parallel_for(tbb::blocked_range<uint32_t>(0, P, 64), [&](auto r) {
            for (uint32_t i = r.begin(); i < r.end(); ++i) {
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
