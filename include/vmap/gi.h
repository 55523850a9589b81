// Diffuse global illumination over the V-map (paper §6.3; docs/gi.md).
//
// Radiosity over the points: B_i = E_i + rho_i * sum_j F_ij B_j, with V_ij from the V-map (a
// link (A, B) means every leaf under A sees every leaf under B; points of one leaf do not
// exchange energy, the V-map says nothing about them). Each point stands for a disc of area
// A_i = pi r_i^2 (its splat radius). The form factor from receiver r to source s is
//
//     F_rs = A_s * K(r, s),   K(r, s) = cos_r cos_s / (pi d^2 + max(A_r, A_s))
//
// (cosines clamped at 0). K is symmetric, so A_r F_rs = A_s F_sr (reciprocity) holds, and
// F_rs <= A_s / max(A_r, A_s) <= 1 for every pair. For two small facing discs far apart it is
// the classical cos cos A / (pi d^2).
//
// The solver is hierarchical radiosity of order 0: nodes carry their points' total area, the
// area-weighted mean position and mean normal (not renormalised, so A_n * dot(mean normal, w)
// is the exact sum of the points' A_k dot(n_k, w)) and the area-weighted mean radiosity. A
// node pair (A, B) of disjoint subtrees is well separated when |c_A - c_B| > theta * (s_A + s_B)
// (s = half the diagonal of the node's content box); theta is the separation parameter.
//
// refine = "blocks" (default): the pairs that top-down refinement from (root, root) leaves
// (well separated node pairs, and point pairs of two leaves that are not) partition the
// leaf-pair matrix into blocks. Every V-map link is split along that partition, and each block
// sums T = A_x A_y K(x, y) over the link parts (x, y) it holds (the finer node of each side);
// receiver A then gathers T / A_A * B_B from B. Only pairs that see each other contribute, and
// the number of blocks grows like classic hierarchical radiosity's (about linearly), not like
// the number of links. Within a block, the visible parts' energy is spread over the receiver
// node (order 0): shadow edges blur at the scale of nodes that theta keeps small against their
// distance.
// refine = "links": every link (A, B) itself moves energy at node level when well separated
// (F = A_B K(A, B), from the node sums); otherwise the larger end is opened (children pairs are
// visible too, since all of A sees all of B) down to leaf pairs, which exchange point to point.
// Exact visibility, but as many interactions as links (which grow faster than the points).
//
// A bounce gathers over the interaction list, pushes the nodes' gathered irradiance down to
// their points, and pulls radiosity back up (area-weighted mean). The larger theta, the finer
// the transfer; as theta -> infinity every transfer is point to point and both modes give the
// brute-force answer (brute_force_radiosity).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "vmap/options.h"
#include "vmap/vec.h"
#include "vmap/visibility_map.h"

namespace vmap {

struct GiParams {
    int bounces = 3;                         // gather steps after B = E; 1 = direct light only
    float theta = 1.0f;                      // separation parameter (> 0): larger is finer, slower
    Backend backend = Backend::kAuto;
    GiRefine refine = GiRefine::kBlocks;     // see above
    uint64_t max_interactions = 1ull << 31;  // refuse a refinement larger than this
    ProgressCallback progress;  // refinement progress (vmap/progress.h); false cancels

    // Throws vmap::Error naming `source` and the field: theta <= 0 or not finite, bounces < 0.
    void check(const std::string& source) const;
};

struct GiStats {
    std::string backend;                 // which backend ran, in words
    std::string note;                    // e.g. why the requested backend was not used
    uint64_t node_interactions = 0;      // receiver/source pairs at node level (one direction)
    uint64_t point_interactions = 0;     // receiver/source pairs point to point (one direction)
    double seconds_setup = 0;            // node sums + refinement + upload (once)
    std::vector<double> seconds_bounce;  // per bounce
    uint64_t interactions() const { return node_interactions + point_interactions; }
};

// The hierarchical solver. Construction does the one-off work (node sums, refinement into an
// interaction list, upload to the GPU); bounce() does one gather step. Throws vmap::Error for
// bad parameters (theta <= 0 or not finite, negative bounces), points without splat radii or
// normals, or a refinement with more than max_interactions entries (lower theta).
class RadiositySolver {
  public:
    RadiositySolver(const VisibilityMap& vm, const GiParams& params, GiStats* stats = nullptr);
    ~RadiositySolver();
    RadiositySolver(const RadiositySolver&) = delete;
    RadiositySolver& operator=(const RadiositySolver&) = delete;

    void reset();   // B = E (emission) at every point
    void bounce();  // B = E + rho * gathered(B)
    int bounces_done() const;
    // Radiosity per point (W/m^2 per channel), octree order (vm.points' order).
    std::vector<Vec3> radiosity() const;
    const GiStats& stats() const;
    // One more bounce, gathered per point from the current solution (no block of receivers
    // shares a value): point i gathers from every node linked to its leaf or an ancestor, at
    // node level (the node's mean radiosity, area and mean normal, seen from the point) when
    // the node is flat and farther than theta x its size from the point, else from its
    // children, down to points. Returns B = E + rho * gathered for the given points (octree
    // positions; all points, in octree order, when empty); the solver's state is unchanged. On
    // all CPU cores. Throws vmap::Error for theta <= 0 or a point out of range.
    std::vector<Vec3> final_gather(float theta, std::span<const uint32_t> points = {}) const;
    // The interaction list (for tests and tools): elements are the octree nodes, then the points
    // at num_nodes + k; receiver e gathers coef[k] * B[src[k]] for k in [row[e], row[e+1]);
    // area[e] is the element's area.
    void interaction_list(std::vector<uint64_t>& row, std::vector<uint32_t>& src,
                          std::vector<float>& coef, std::vector<double>& area) const;

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// Runs params.bounces bounces from B = E; radiosity per point in octree order.
std::vector<Vec3> solve_radiosity(const VisibilityMap& vm, const GiParams& params,
                                  GiStats* stats = nullptr);

// The reference: every visible point pair (leaves linked by the V-map) exchanges energy point to
// point with the same form factor, computed on the fly; O(visible point pairs) per bounce, on
// all CPU cores. If per_bounce is given, it receives the radiosity after each bounce.
// seconds_per_bounce (if given) receives each bounce's time, pairs (if given) the number of
// visible point pairs one bounce sums over.
std::vector<Vec3> brute_force_radiosity(const VisibilityMap& vm, int bounces,
                                        std::vector<std::vector<Vec3>>* per_bounce = nullptr,
                                        std::vector<double>* seconds_per_bounce = nullptr,
                                        uint64_t* pairs = nullptr);

// The point-level kernel K(r, s) above (the form factor is A_s * K).
float gi_kernel(Vec3 pr, Vec3 nr, float ar, Vec3 ps, Vec3 ns, float as);

// Total power sum_i A_i B_i per channel (W, areas in input units), points in octree order.
Vec3 total_power(const VisibilityMap& vm, const std::vector<Vec3>& radiosity);

// Relative RMS difference over points: sqrt(sum |a_i - b_i|^2 / sum |b_i|^2) (all channels).
double relative_rms(const std::vector<Vec3>& a, const std::vector<Vec3>& b);

// Display colours from radiosity, linear RGB in [0, 1]: c = clamp(exposure * B, 0, 1) per
// channel (the renderer and the PLY writer apply the sRGB curve). B is already albedo-weighted
// (B = E + rho H). With exposure <= 0 it is chosen so that the 95th percentile of the
// brightest channel among points without emission maps to 0.8 (lights saturate to white).
// Returns the exposure used. Throws vmap::Error for a non-finite exposure.
float tone_map(const VisibilityMap& vm, const std::vector<Vec3>& radiosity, float exposure,
               std::vector<Vec3>& colors);

}  // namespace vmap
