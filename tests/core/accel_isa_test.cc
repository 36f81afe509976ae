// The same hits on every x86-64 CPU: Embree picks its kernels by the CPU's vector
// instructions, and its AVX2 and AVX-512 kernels fuse multiplies and adds, so their hits
// differ from the others' in the last bits; an image would then depend on the machine that
// rendered it. Accel caps Embree at AVX (AccelOptions::max_isa). This test traces the same
// rays through Accels capped at SSE2, SSE4.2 and AVX (those this CPU has) and requires every
// hit and every occlusion answer to be the same bits. The cap is not enough across vendors:
// Embree's t and barycentrics come from an approximate reciprocal (rcpps) whose last bits
// differ between Intel's and AMD's CPUs, so Accel computes them again from the triangle
// Embree found with IEEE operations alone (recompute_triangle_hit). Then even Embree's AVX2
// and AVX-512 kernels, where the CPU has them, give the same hits but for the rare ray
// through an edge that they give to the neighbouring triangle: at most 1 in 10,000 here
// (they changed about half of all hits before); counted, printed and bounded.
#include <gtest/gtest.h>

#include <bit>
#include <cstdio>
#include <string>
#include <vector>

#include "core/accel/accel.h"
#include "core/sampling/sampler.h"
#include "core/sampling/warp.h"
#include "core/scene/load.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

struct Traced {
  std::vector<Hit> hits;
  std::vector<bool> found, occluded;
};

// Rays from points spread through the scene's bounds in directions over the sphere (as
// tessera_bench's raw rays), each also asked for occlusion up to a distance in the box's size.
std::vector<Ray> rays_for(const Scene& scene, size_t n) {
  const Bounds b = scene.object_bounds();
  const Vec3 size = b.hi - b.lo;
  std::vector<Ray> rays(n);
  for (size_t i = 0; i < n; ++i) {
    Sampler s(5, i, 0);
    const Vec2 u = s.next_2d();
    const Vec2 w = s.next_2d();
    const Vec3 o{b.lo.x + size.x * u.x, b.lo.y + size.y * u.y, b.lo.z + size.z * w.x};
    rays[i] = Ray{o, square_to_uniform_sphere(s.next_2d()), 0, 1e30f};
    rays[i].tmax = i % 2 ? 1e30f : (size.x + size.y + size.z) * w.y;
  }
  return rays;
}

Traced trace(const Scene& scene, const std::vector<Ray>& rays, const char* isa) {
  AccelOptions options;
  options.max_isa = isa;
  const Accel accel(scene, options);
  Traced t;
  t.hits.resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    t.found.push_back(accel.intersect(rays[i], &t.hits[i]));
    t.occluded.push_back(accel.occluded(rays[i]));
  }
  return t;
}

bool same_bits(const Hit& a, const Hit& b) {
  auto bits = [](float f) { return std::bit_cast<uint32_t>(f); };
  return bits(a.t) == bits(b.t) && bits(a.u) == bits(b.u) && bits(a.v) == bits(b.v) && a.shape == b.shape &&
         a.prim == b.prim && a.instance == b.instance && a.is_sphere == b.is_sphere;
}

// How many rays of `b` differ from `a` in any bit of their hit or occlusion answer.
size_t differences(const Traced& a, const Traced& b) {
  size_t n = 0;
  for (size_t i = 0; i < a.hits.size(); ++i)
    n += a.found[i] != b.found[i] || a.occluded[i] != b.occluded[i] || (a.found[i] && !same_bits(a.hits[i], b.hits[i]));
  return n;
}

void expect_same_on_every_isa(const std::string& path) {
  const Scene scene = load_scene(path);
  const std::vector<Ray> rays = rays_for(scene, 200000);
  const Traced reference = trace(scene, rays, "sse2");
  size_t hits = 0;
  for (bool f : reference.found) hits += f;
  ASSERT_GT(hits, rays.size() / 4) << path << ": the rays should mostly hit";
  __builtin_cpu_init();
  if (__builtin_cpu_supports("sse4.2")) {
    EXPECT_EQ(differences(reference, trace(scene, rays, "sse4.2")), 0u) << path;
  }
  if (__builtin_cpu_supports("avx")) {
    EXPECT_EQ(differences(reference, trace(scene, rays, "avx")), 0u) << path;
  }
  AccelOptions defaults;
  EXPECT_EQ(std::string(defaults.max_isa), "avx");
  const std::pair<const char*, bool> wide_isas[] = {{"avx2", __builtin_cpu_supports("avx2") != 0},
                                                    {"avx512", __builtin_cpu_supports("avx512f") != 0}};
  for (const auto& [wide, has] : wide_isas) {
    if (!has) continue;
    const size_t changed = differences(reference, trace(scene, rays, wide));
    std::printf("%s: %zu of %zu rays would change with Embree's %s kernels\n", path.c_str(), changed, rays.size(),
                wide);
    EXPECT_LE(changed, rays.size() / 10000) << path << ": " << wide;
  }
}

TEST(AccelIsa, CornellSpheresHitTheSameOnEveryCappedIsa) {
  expect_same_on_every_isa(testing::source_path("scenes/cornell-spheres.dae"));
}

TEST(AccelIsa, GltfSceneHitsTheSameOnEveryCappedIsa) {
  expect_same_on_every_isa(testing::source_path("scenes/material-spheres.gltf"));
}

TEST(AccelIsa, DragonHitsTheSameOnEveryCappedIsa) {
  TESSERA_REQUIRE_SHARED_SCENE(path, "CBdragon.dae");
  expect_same_on_every_isa(path);
}

}  // namespace
}  // namespace tessera
