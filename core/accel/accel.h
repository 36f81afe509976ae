// Ray-scene intersection. The only interface the render kernel sees; Embree stays behind
// it (embree_accel.cc is the only file that includes embree3/rtcore.h).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "core/math/ray.h"
#include "core/math/vec.h"
#include "core/scene/scene.h"

namespace tessera {

struct Hit {
  float t = 0;
  float u = 0, v = 0;  // triangle barycentrics of vertices 1 and 2
  Vec3 ng;             // unnormalised geometric normal (triangle winding / sphere outward)
  uint32_t shape = 0;  // mesh index, or sphere index when is_sphere
  uint32_t prim = 0;   // triangle index within the mesh
  // Scene::instances index of an instanced mesh's hit (ng then in its object space), or -1.
  int32_t instance = -1;
  bool is_sphere = false;
};

struct AccelOptions {
  // Embree's RTC_SCENE_FLAG_ROBUST: watertight triangle tests, so a ray through a shared edge
  // or vertex of a closed mesh cannot slip between its triangles. The renderer always sets
  // it; the watertightness tests and tessera_bench also build without it, to measure what
  // it buys and costs (docs/ray-offsets.md).
  bool robust = true;
  // The widest of the CPU's vector instruction sets Embree may use (its "max_isa"). Its AVX2
  // and AVX-512 kernels fuse multiplies and adds, so their hits differ from the SSE and AVX
  // kernels' in the last bits, and from each other's: an image would depend on the CPU that
  // rendered it (and a farm of mixed machines would not give tessera render's bits). The
  // SSE2, SSE4.2 and AVX kernels agree (accel_isa_test.cc). A triangle hit's t and
  // barycentrics are computed again by Accel itself (IEEE operations alone: Embree's come
  // from an approximate reciprocal whose last bits differ between Intel's and AMD's CPUs),
  // so only Embree's choice of triangle and its occlusion answers reach the image. On an
  // AVX2 machine the cap costs nothing measurable (docs/performance.md).
  const char* max_isa = "avx";
  // A triangle hit's t and barycentrics computed again by IEEE operations (above); off,
  // Embree's as they come: tessera_bench's raw rays, which measure Embree alone.
  bool own_hits = true;
};

class Accel {
 public:
  // Builds the acceleration structure; `scene` must outlive the Accel. Each instanced
  // mesh's BVH is built once and placed by its instances. Throws
  // std::runtime_error if Embree reports an error.
  explicit Accel(const Scene& scene, AccelOptions options = {});
  // The static part of an animated scene: every mesh but those marked in `skip`, and the
  // spheres. Built once for all frames. (Animated scenes have no instances.)
  Accel(const Scene& scene, const std::vector<bool>& skip, AccelOptions options = {});
  // One pose of an animated scene: the meshes marked in `moving` are built here from
  // `scene` (the pose, in world space); everything else is `fixed` (built from the same
  // scene's static part with skip = moving), reached through an instance with the identity
  // transform, so its BVH is not built again. Hits report mesh indices of `scene` either way.
  Accel(const Scene& scene, std::shared_ptr<const Accel> fixed, const std::vector<bool>& moving);
  ~Accel();
  Accel(const Accel&) = delete;
  Accel& operator=(const Accel&) = delete;

  bool intersect(const Ray& ray, Hit* hit) const;
  bool occluded(const Ray& ray) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Exact ray-sphere intersection in double precision: the nearest root in (tmin, tmax], or
// a negative value if there is none. Exposed for tests.
double intersect_sphere(const Vec3& center, float radius, const Ray& ray);

}  // namespace tessera
