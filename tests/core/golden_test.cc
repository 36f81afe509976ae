// Golden images: the film bits of small renders, pinned as hashes.
//
// The hashes were taken from `tessera render`'s code path before the frame plan replaced
// the pass-by-pass local renderer (commit fba7d1d): a schedule change that alters one bit of
// one pixel fails here. They depend on the compiler's floating-point code generation, so a
// compiler upgrade may change them all at once; then re-derive them from a build of the
// commit above, never from the code under test. They depend on Embree's kernels too: taken
// first on a machine whose Embree ran neither its AVX2 nor its capped kernels (AVX-512, by
// inference), they were re-derived (2026-11-27)
// when Accel capped Embree at AVX (accel.h), from the commit before the cap with only the
// cap added (and equal with SSE2, SSE4.2 and AVX). That was not enough: Embree's t and
// barycentrics come from an approximate reciprocal whose last bits differ between Intel's
// and AMD's CPUs (on an Intel CPU every golden but no_nee failed). Re-derived (2026-11-29)
// from the commit before Accel computed them itself (recompute_triangle_hit, IEEE
// operations only) with only that added, on an Intel Xeon (AVX-512); with it, Embree's
// AVX2 and AVX-512 kernels give the same hits too (accel_isa_test.cc).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>

#include "core/scene/load.h"
#include "tests/core/render_helpers.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

// FNV-1a over every pixel's r, g, b, lum2 and n (field by field: the struct has padding).
uint64_t film_hash(const Film& film) {
  uint64_t h = 1469598103934665603ull;
  auto add = [&](const void* p, size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  for (const PixelSums& p : film.pixels()) {
    add(&p.r, 8);
    add(&p.g, 8);
    add(&p.b, 8);
    add(&p.lum2, 8);
    add(&p.n, 4);
  }
  return h;
}

RenderSettings base() {
  RenderSettings s;
  s.camera.width = 64;
  s.camera.height = 48;
  s.spp = 12;
  s.pass_spp = 5;
  s.max_depth = 8;
  s.seed = 7;
  // The goldens pin the path tracer's bits (light_tracer_test and the farm tests hold the
  // light tracer's: against the path tracer in expectation, and bit for bit across splits).
  s.light_tracer = RenderSettings::LightTracer::kOff;
  return s;
}

struct Golden {
  const char* name;
  const char* scene;
  RenderSettings settings;
  uint64_t hash;
};

std::vector<Golden> goldens() {
  std::vector<Golden> g;
  g.push_back({"plain", "scenes/cornell-spheres.dae", base(), 0x095d24094a57f7c4ull});
  RenderSettings adaptive = base();
  adaptive.spp = 64;
  adaptive.adaptive = true;
  adaptive.adaptive_batch = 8;
  adaptive.adaptive_tolerance = 0.2f;
  g.push_back({"adaptive", "scenes/cornell-spheres.dae", adaptive, 0xef79a1f2cd693093ull});
  RenderSettings lens = base();
  lens.camera.lens_radius = 0.1f;
  lens.camera.focal_distance = 4.5f;
  g.push_back({"thin_lens", "scenes/cornell-spheres.dae", lens, 0xaf1366db1cfff7c9ull});
  RenderSettings window = base();
  window.window = Rect{10, 7, 23, 19};
  g.push_back({"window", "scenes/cornell-spheres.dae", window, 0x6493f0c394e2e83eull});
  RenderSettings estimators = base();
  estimators.nee = false;
  g.push_back({"no_nee", "scenes/cornell-spheres.dae", estimators, 0xa8dcf954eb37cd57ull});
  estimators.nee = true;
  estimators.mis = false;
  g.push_back({"no_mis", "scenes/cornell-spheres.dae", estimators, 0xc2262348b7ef6b4cull});
  RenderSettings gltf = base();
  gltf.camera.framing = Framing::kFile;
  g.push_back({"gltf", "scenes/dof-row.gltf", gltf, 0xd64462206d1768efull});
  return g;
}

TEST(Golden, FilmsKeepTheirBits) {
  for (const Golden& g : goldens()) {
    const Scene scene = load_scene(testing::source_path(g.scene));
    const uint64_t h = film_hash(testing::render(scene, g.settings).film);
    EXPECT_EQ(h, g.hash) << g.name << ": 0x" << std::hex << h;
  }
}

}  // namespace
}  // namespace tessera
