// Exact point-pair visibility from a scene's triangles with Embree 3 occlusion rays (any hit,
// early exit), the ground truth of `vmap validate`.
#include <embree3/rtcore.h>
#include <fmt/format.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>

#include "vmap/error.h"
#include "vmap/validate.h"

namespace vmap {
namespace {

RTCDevice dev(void* p) { return static_cast<RTCDevice>(p); }
RTCScene scn(void* p) { return static_cast<RTCScene>(p); }

void check(RTCDevice d, const std::string& source, const char* what) {
    const RTCError e = rtcGetDeviceError(d);
    if (e != RTC_ERROR_NONE)
        throw Error(fmt::format("{}: Embree: {} failed (error {})", source, what, int(e)));
}

}  // namespace

ExactVisibility::ExactVisibility(const std::vector<SceneSurface>& surfaces,
                                 const std::string& source) {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d)
        throw Error(fmt::format("{}: Embree: no device (error {})", source,
                                int(rtcGetDeviceError(nullptr))));
    device_ = d;
    try {
        RTCScene s = rtcNewScene(d);
        scene_ = s;
        check(d, source, "rtcNewScene");
        rtcSetSceneBuildQuality(s, RTC_BUILD_QUALITY_HIGH);
        for (const SceneSurface& surf : surfaces) {
            const Mesh& m = surf.mesh;
            if (m.triangles.empty()) continue;
            RTCGeometry g = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_TRIANGLE);
            auto* v = static_cast<float*>(
                rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                        3 * sizeof(float), m.vertices.size()));
            auto* ix = static_cast<unsigned*>(
                rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                        3 * sizeof(unsigned), m.triangles.size()));
            if (!v || !ix) {
                rtcReleaseGeometry(g);
                check(d, source, "rtcSetNewGeometryBuffer");
                throw Error(fmt::format("{}: Embree: no buffer for {}", source, surf.name));
            }
            for (size_t k = 0; k < m.vertices.size(); ++k) {
                v[3 * k] = m.vertices[k].x;
                v[3 * k + 1] = m.vertices[k].y;
                v[3 * k + 2] = m.vertices[k].z;
            }
            for (size_t k = 0; k < m.triangles.size(); ++k)
                for (int c = 0; c < 3; ++c) {
                    if (m.triangles[k][c] >= m.vertices.size()) {
                        rtcReleaseGeometry(g);
                        throw Error(fmt::format("{}: surface {}: triangle {} names vertex {}",
                                                source, surf.name, k, m.triangles[k][c]));
                    }
                    ix[3 * k + c] = m.triangles[k][c];
                }
            rtcCommitGeometry(g);
            const unsigned id = rtcAttachGeometry(s, g);
            rtcReleaseGeometry(g);
            if (surface_of_geometry_.size() <= id) surface_of_geometry_.resize(id + 1, -1);
            surface_of_geometry_[id] = int32_t(&surf - surfaces.data());
            triangles_ += m.triangles.size();
        }
        if (triangles_ == 0) throw Error(fmt::format("{}: the scene has no triangles", source));
        rtcCommitScene(s);
        check(d, source, "rtcCommitScene");
    } catch (...) {
        if (scene_) rtcReleaseScene(scn(scene_));
        rtcReleaseDevice(d);
        throw;
    }
}

ExactVisibility::~ExactVisibility() {
    if (scene_) rtcReleaseScene(scn(scene_));
    if (device_) rtcReleaseDevice(dev(device_));
}

bool ExactVisibility::occluded(Vec3 a, Vec3 b, float t0, float t1) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRay r;
    r.org_x = a.x, r.org_y = a.y, r.org_z = a.z;
    r.dir_x = b.x - a.x, r.dir_y = b.y - a.y, r.dir_z = b.z - a.z;
    r.tnear = t0;
    r.tfar = t1;
    r.time = 0;
    r.mask = 0xFFFFFFFFu;
    r.id = 0;
    r.flags = 0;
    rtcOccluded1(scn(scene_), &ctx, &r);
    // Embree marks a hit by setting tfar to -inf.
    return r.tfar < 0;
}

ExactVisibility::Hit ExactVisibility::intersect(Vec3 org, Vec3 dir, float t0, float t1) const {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    rh.ray.org_x = org.x, rh.ray.org_y = org.y, rh.ray.org_z = org.z;
    rh.ray.dir_x = dir.x, rh.ray.dir_y = dir.y, rh.ray.dir_z = dir.z;
    rh.ray.tnear = t0;
    rh.ray.tfar = t1;
    rh.ray.time = 0;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scn(scene_), &ctx, &rh);
    Hit h;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID || rh.hit.geomID >= surface_of_geometry_.size())
        return h;
    h.surface = surface_of_geometry_[rh.hit.geomID];
    h.t = rh.ray.tfar;
    // Embree's Ng is the unnormalised (v1 - v0) x (v2 - v0): the winding's outward side.
    h.normal = Vec3{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z};
    const float len = length(h.normal);
    if (len > 0) h.normal = h.normal / len;
    return h;
}

bool ExactVisibility::facing(Vec3 a, Vec3 na, Vec3 b, Vec3 nb) {
    // Points on one flat wall have n . d = 0 up to rounding; a relative 1e-6 keeps rounding noise
    // from calling them facing (a grazing ray along the wall would decide at random).
    const Vec3 d = b - a;
    const float lim = 1e-6f * length(d);
    return dot(na, d) > lim && -dot(nb, d) > lim;
}

bool ExactVisibility::visible(Vec3 a, Vec3 na, Vec3 b, Vec3 nb, float offset) const {
    if (!facing(a, na, b, nb)) return false;
    const float len = length(b - a);
    if (!(len > 2 * offset)) return true;  // nothing fits between them
    const float f = offset / len;
    return !occluded(a, b, f, 1.f - f);
}

void ExactVisibility::occluded_packets(const std::vector<Vec3>& from, const std::vector<Vec3>& to,
                                       float t0, float t1, std::vector<uint8_t>& out) const {
    const size_t n = from.size();
    out.assign(n, 0);
    const size_t packets = (n + 15) / 16;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, packets, 64), [&](const auto& range) {
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
        alignas(64) RTCRay16 r;
        alignas(64) int valid[16];
        for (size_t pk = range.begin(); pk < range.end(); ++pk) {
            const size_t k0 = pk * 16;
            for (int i = 0; i < 16; ++i) {
                const size_t k = k0 + i;
                valid[i] = k < n ? -1 : 0;
                const Vec3 a = k < n ? from[k] : Vec3{}, b = k < n ? to[k] : Vec3{1, 0, 0};
                r.org_x[i] = a.x, r.org_y[i] = a.y, r.org_z[i] = a.z;
                r.dir_x[i] = b.x - a.x, r.dir_y[i] = b.y - a.y, r.dir_z[i] = b.z - a.z;
                r.tnear[i] = t0, r.tfar[i] = t1, r.time[i] = 0;
                r.mask[i] = 0xFFFFFFFFu, r.id[i] = unsigned(i), r.flags[i] = 0;
            }
            rtcOccluded16(valid, scn(scene_), &ctx, &r);
            for (int i = 0; i < 16 && k0 + i < n; ++i) out[k0 + i] = r.tfar[i] < 0;
        }
    });
}

}  // namespace vmap
