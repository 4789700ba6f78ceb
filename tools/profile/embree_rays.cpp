// mobirt_embree_rays: Embree 3 on the rays of mobirt's traversal pass, for the Mrays/s ratio.
//
// The traversal pass of one frame traces the primary rays (closest hit) and, from their hits, one
// shadow ray per light (any hit). This tool makes the same rays (primary_rays(); hits from the CPU
// kd-tree traversal, which equals the GPU's; shadow rays from shadow_rays()) and traces them with
// Embree 3 on 2 threads (or --threads N), each ray on its own (rtcIntersect1 / rtcOccluded1),
// --repeat times, and prints the median Mrays/s of:
//   intersect1      every ray, primary and shadow, with rtcIntersect1 (closest hit): the baseline
//                   of issue 5's traversal target (Embree rtcIntersect1 on the same rays)
//   mixed           primaries with rtcIntersect1, shadow rays with rtcOccluded1: what the pass does
// plus Embree's BVH build time (RTC_BUILD_QUALITY_MEDIUM, the default).
//
// Usage: mobirt_embree_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH]
//        [--repeat N] [--threads N]
#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "raytree/hits.h"
#include "raytree/rays.h"
#include "profile_scene.h"

namespace mobirt {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Runs f(i) for i in [0, n) on `threads` threads, in chunks of 64 rays taken in turn.
template <class F>
void parallel(size_t n, int threads, F&& f) {
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (;;) {
      const size_t start = next.fetch_add(64);
      if (start >= n) return;
      for (size_t i = start; i < std::min(n, start + 64); ++i) f(i);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
}

RTCRay embree_ray(const Ray& r) {
  RTCRay ray{};
  ray.org_x = r.origin.x;
  ray.org_y = r.origin.y;
  ray.org_z = r.origin.z;
  ray.dir_x = r.direction.x;
  ray.dir_y = r.direction.y;
  ray.dir_z = r.direction.z;
  ray.tnear = r.tmin;
  ray.tfar = r.tmax;
  ray.mask = 0xFFFFFFFFu;
  return ray;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int run(int argc, char** argv) {
  int threads = 2;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
      threads = std::max(1, std::atoi(argv[++i]));
    } else {
      args.push_back(argv[i]);
    }
  }
  const profile::ProfileScene p = profile::load_profile_scene(
      int(args.size()), args.data(),
      "usage: mobirt_embree_rays SCENE [--camera SPEC] [--light SPEC]... [--mtl F] [--size WxH] [--repeat N] "
      "[--threads N]");

  // The pass's rays: primaries, and the shadow rays of their hits (hits as the GPU finds them).
  const RayBatch batch = primary_rays(p.camera, p.width, p.height);
  std::vector<Ray> primary, shadow;
  for (uint32_t i = 0; i < batch.count(); ++i) {
    const Ray ray = batch.ray(i);
    primary.push_back(ray);
    const Hit hit = traverse(p.tree, ray, p.stack);
    if (!hit.valid()) continue;
    for (const std::optional<Ray>& s : shadow_rays(p.tree, p.scene.lights, hit.prim, ray, hit.t, ShadowSettings{})) {
      if (s) shadow.push_back(*s);
    }
  }

  RTCDevice device = rtcNewDevice(("threads=" + std::to_string(threads)).c_str());
  if (!device) throw Error(ErrorKind::Internal, "rtcNewDevice failed");
  RTCScene scene = rtcNewScene(device);
  const auto build_start = Clock::now();
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  const std::vector<glm::vec3>& positions = p.scene.mesh.positions;
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0,
                                                                RTC_FORMAT_FLOAT3, 3 * sizeof(float),
                                                                positions.size()));
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                 3 * sizeof(unsigned), positions.size() / 3));
  for (size_t i = 0; i < positions.size(); ++i) {
    vertices[3 * i + 0] = positions[i].x;
    vertices[3 * i + 1] = positions[i].y;
    vertices[3 * i + 2] = positions[i].z;
    indices[i] = unsigned(i);
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);
  const double build_ms = seconds_since(build_start) * 1e3;

  std::vector<double> intersect_ms, mixed_ms;
  std::atomic<size_t> primary_hits{0}, occluded{0};
  for (int r = 0; r < std::max(1, p.repeat) + 1; ++r) {  // the first round warms up
    primary_hits = 0;
    occluded = 0;
    auto closest = [&](const Ray& ray) {
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      RTCRayHit rh{};
      rh.ray = embree_ray(ray);
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &context, &rh);
      return rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    };
    auto start = Clock::now();
    parallel(primary.size() + shadow.size(), threads, [&](size_t i) {
      closest(i < primary.size() ? primary[i] : shadow[i - primary.size()]);
    });
    const double a = seconds_since(start) * 1e3;
    start = Clock::now();
    parallel(primary.size() + shadow.size(), threads, [&](size_t i) {
      if (i < primary.size()) {
        if (closest(primary[i])) ++primary_hits;
        return;
      }
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      RTCRay ray = embree_ray(shadow[i - primary.size()]);
      rtcOccluded1(scene, &context, &ray);
      if (ray.tfar < 0.0f) ++occluded;
    });
    const double b = seconds_since(start) * 1e3;
    if (r > 0) {
      intersect_ms.push_back(a);
      mixed_ms.push_back(b);
    }
  }
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);

  const double rays = double(primary.size() + shadow.size());
  const double ia = median(intersect_ms), mx = median(mixed_ms);
  std::printf("%s: %zu triangles, %zux%d... %zu primary + %zu shadow rays, Embree 3, %d threads, median of %d\n",
              p.path.c_str(), positions.size() / 3, size_t(p.width), p.height, primary.size(), shadow.size(),
              threads, p.repeat);
  std::printf("bvh build            %8.2f ms\n", build_ms);
  std::printf("intersect1           %8.2f ms  %6.2f Mrays/s   (every ray closest-hit)\n", ia, rays / (ia * 1e3));
  std::printf("intersect1+occluded1 %8.2f ms  %6.2f Mrays/s   (%zu primary hits, %zu shadow rays occluded)\n", mx,
              rays / (mx * 1e3), size_t(primary_hits), size_t(occluded));
  return 0;
}

}  // namespace
}  // namespace mobirt

int main(int argc, char** argv) { return mobirt::profile::run_tool("mobirt_embree_rays", argc, argv, mobirt::run); }
