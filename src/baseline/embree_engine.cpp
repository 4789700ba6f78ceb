#include "baseline/embree_engine.h"

#include <embree3/rtcore.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include "core/error.h"
#include "layout.h"

namespace mobirt {

namespace {

[[noreturn]] void embree_failed(RTCDevice device, const std::string& what) {
  const RTCError code = device ? rtcGetDeviceError(device) : RTC_ERROR_UNKNOWN;
  throw Error(ErrorKind::Internal, "Embree: " + what + " failed (error " + std::to_string(int(code)) + ")");
}

RTCRay to_embree(const Ray& ray) {
  RTCRay r{};
  r.org_x = ray.origin.x;
  r.org_y = ray.origin.y;
  r.org_z = ray.origin.z;
  r.dir_x = ray.direction.x;
  r.dir_y = ray.direction.y;
  r.dir_z = ray.direction.z;
  r.tnear = ray.tmin;
  r.tfar = ray.tmax;
  r.mask = ~0u;
  return r;
}

}  // namespace

struct EmbreeEngine::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  RTCGeometry geometry = nullptr;
  size_t capacity = 0;  // triangles the geometry's buffers hold
  bool dynamic_low = true;
  // The build's TBB arena of EmbreeOptions::threads (none for 0: the calling thread's). Made once
  // and kept, as a renderer on Embree would keep it: an arena made for each build paid for its
  // workers joining a new arena every frame.
  std::unique_ptr<tbb::task_arena> arena;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (geometry) rtcReleaseGeometry(geometry);
    if (device) rtcReleaseDevice(device);
  }

  // A new geometry when the triangle count changes (buffers are sized to it); otherwise the same
  // geometry, its vertex buffer rewritten: the per-frame path of a dynamic scene.
  void ensure_geometry(size_t triangles) {
    if (geometry && capacity == triangles) return;
    if (geometry) {
      rtcDetachGeometry(scene, 0);
      rtcReleaseGeometry(geometry);
      geometry = nullptr;
      capacity = 0;
    }
    if (triangles == 0) return;  // an empty scene: nothing attached, every ray misses
    geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!geometry) embree_failed(device, "rtcNewGeometry");
    // Embree reads 16 bytes at the last vertex: the buffers are allocated by Embree, padded.
    rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float),
                            3 * triangles);
    auto* index = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0,
                                                                 RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), triangles));
    if (triangles && !index) embree_failed(device, "rtcSetNewGeometryBuffer");
    for (uint32_t i = 0; i < 3 * triangles; ++i) index[i] = i;
    if (dynamic_low) rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_LOW);
    rtcAttachGeometryByID(scene, geometry, 0);
    capacity = triangles;
  }
};

EmbreeEngine::EmbreeEngine(const EmbreeOptions& options) : impl_(std::make_unique<Impl>()) {
  // No "threads=N" in the device's configuration: Embree 3 turns it into a process-wide TBB limit
  // (tbb::global_control) that would cap every other TBB loop of the process too, mobirt's own
  // frame stages (core/parallel.h) included. The build runs in a TBB arena of N threads instead,
  // which Embree's TBB tasks stay in.
  impl_->device = rtcNewDevice(nullptr);
  if (!impl_->device) embree_failed(nullptr, "rtcNewDevice");
  if (options.threads > 0) impl_->arena = std::make_unique<tbb::task_arena>(int(options.threads));
  impl_->scene = rtcNewScene(impl_->device);
  if (!impl_->scene) embree_failed(impl_->device, "rtcNewScene");
  impl_->dynamic_low = options.dynamic_low;
  rtcSetSceneFlags(impl_->scene, options.dynamic_low ? RTC_SCENE_FLAG_DYNAMIC : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(impl_->scene, options.dynamic_low ? RTC_BUILD_QUALITY_LOW : RTC_BUILD_QUALITY_MEDIUM);
}

EmbreeEngine::~EmbreeEngine() = default;

std::string EmbreeEngine::version() {
  return "Embree " + std::to_string(RTC_VERSION_MAJOR) + "." + std::to_string(RTC_VERSION_MINOR) + "." +
         std::to_string(RTC_VERSION_PATCH);
}

void EmbreeEngine::build(const Scene& scene) {
  // Embree gets triangles: analytic shapes are the caller's to tessellate (scene/tessellate.h).
  if (!scene.shapes.empty()) {
    throw Error(ErrorKind::Internal, "Embree engine: the scene's analytic shapes must be tessellated first");
  }
  build(scene.mesh.positions);
}

void EmbreeEngine::build(std::span<const glm::vec3> positions) {
  const size_t n = positions.size() / 3;
  impl_->ensure_geometry(n);
  float* v = impl_->geometry ? static_cast<float*>(rtcGetGeometryBufferData(impl_->geometry, RTC_BUFFER_TYPE_VERTEX, 0))
                             : nullptr;
  triangles_.triangles.resize(3 * n);
  triangles_.bounds = Aabb{};
  for (size_t i = 0; i < 3 * n; ++i) {
    const glm::vec3& p = positions[i];
    v[4 * i + 0] = p.x;
    v[4 * i + 1] = p.y;
    v[4 * i + 2] = p.z;
    v[4 * i + 3] = 0.0f;
    triangles_.triangles[i] = glm::vec4(p, 0.0f);
    triangles_.bounds.extend(p);
  }
  if (impl_->geometry) {
    rtcUpdateGeometryBuffer(impl_->geometry, RTC_BUFFER_TYPE_VERTEX, 0);
    rtcCommitGeometry(impl_->geometry);
  }
  if (impl_->arena) {
    impl_->arena->execute([&] { rtcCommitScene(impl_->scene); });
  } else {
    rtcCommitScene(impl_->scene);
  }
  if (rtcGetDeviceError(impl_->device) != RTC_ERROR_NONE) embree_failed(impl_->device, "rtcCommitScene");
}

Hit EmbreeEngine::closest(const Ray& ray) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh{};
  rh.ray = to_embree(ray);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  Hit hit;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return hit;
  hit.prim = int32_t(rh.hit.primID);
  hit.t = rh.ray.tfar;
  hit.u = rh.hit.u;  // Embree's u, v: the weights of v1 and v2, as ours
  hit.v = rh.hit.v;
  return hit;
}

bool EmbreeEngine::occluded(const Ray& ray) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRay r = to_embree(ray);
  rtcOccluded1(impl_->scene, &context, &r);
  return r.tfar == -std::numeric_limits<float>::infinity();
}

}  // namespace mobirt
