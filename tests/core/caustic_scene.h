// The caustic test scenes and comparisons the light tracer's tests share
// (light_tracer_test.cc, light_tracer_edges_test.cc): a floor, a glass or mirror sphere
// over it and a rect light (or a point light) above, seen by a file camera; estimates of a
// film's blocks with their standard errors.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <optional>

#include "core/render/settings.h"
#include "core/scene/scene.h"
#include "tests/core/render_helpers.h"

namespace tessera::testing::caustics {

using LT = RenderSettings::LightTracer;

inline Material diffuse(float albedo) {
  Material m;
  m.kind = Material::Kind::kDiffuse;
  m.reflectance = Rgb(albedo);
  return m;
}
inline Material glass() {
  Material m;
  m.kind = Material::Kind::kGlass;
  m.reflectance = Rgb(1.0f);
  m.transmittance = Rgb(1.0f);
  m.ior = 1.5f;
  return m;
}
inline Material mirror() {
  Material m;
  m.kind = Material::Kind::kMirror;
  m.reflectance = Rgb(1.0f);
  return m;
}

// A diffuse floor (y = 0, [-2, 2]^2) under a sphere of `caster` (centre (0, 0.6, 0),
// radius 0.5; none when `caster_present` is false), lit by a rect light at y = 2.2 or
// a physical point light (1 / d^2) at `point_at`, seen from above at an angle.
// `lift`: the whole scene moved up by it (its light at y = 2.2 + lift); `lamp`: the rect
// light's side; `power`: its radiance times this.
inline Scene caustic_scene(Material caster, bool caster_present = true, std::optional<Vec3> point_at = std::nullopt,
                           float lift = 0, float lamp = 0.8f, float power = 1) {
  Scene s;
  s.materials.push_back(diffuse(0.8f));
  s.materials.push_back(caster);
  Mesh floor;
  floor.name = "floor";
  floor.positions = {{-2, 0, -2}, {2, 0, -2}, {2, 0, 2}, {-2, 0, 2}};
  floor.indices = {0, 2, 1, 0, 3, 2};
  floor.material = 0;
  s.meshes.push_back(floor);
  if (caster_present) s.spheres.push_back(Sphere{"caster", {0, 0.6f, 0}, 0.5f, 1, -1});
  Light l;
  if (point_at) {
    l.kind = Light::Kind::kPoint;
    l.position = *point_at;
    l.color = Rgb(4.0f);
    l.att_constant = 0;
    l.att_quadratic = 1;
  } else {
    l.kind = Light::Kind::kRect;
    l.name = "lamp";
    l.position = {0.2f, 2.2f, 0.1f};
    l.edge_x = {lamp, 0, 0};  // large enough that the path tracer alone converges in a test's time
    l.edge_y = {0, 0, lamp};
    l.normal = {0, -1, 0};
    l.area = lamp * lamp;
    l.color = Rgb(6.0f * 0.64f / l.area * power);
  }
  s.lights.push_back(l);
  s.camera.present = true;
  s.camera.eye = {0, 2.6f, 2.6f};
  s.camera.forward = normalize(Vec3{0, -2.6f, -2.6f});
  s.camera.up = {0, 1, 0};
  s.camera.xfov_deg = 50;
  s.camera.aspect_ratio = 4.0 / 3.0;
  for (Mesh& m : s.meshes)
    for (Vec3& p : m.positions) p.y += lift;
  for (Sphere& sp : s.spheres) sp.center.y += lift;
  s.lights[0].position.y += lift;
  s.camera.eye.y += lift;
  s.finalize();
  return s;
}

inline RenderSettings caustic_settings(LT mode, int spp) {
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = 32;
  s.camera.height = 24;
  s.spp = spp;
  s.max_depth = 8;
  s.light_tracer = mode;
  return s;
}

inline bool same_sums(const std::vector<PixelSums>& a, const std::vector<PixelSums>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)  // field by field: PixelSums has padding
    if (std::memcmp(&a[i].r, &b[i].r, 4 * sizeof(double)) != 0 || a[i].n != b[i].n) return false;
  return true;
}
inline bool same_bits(const Film& a, const Film& b) {
  return same_sums(a.pixels(), b.pixels()) && same_sums(a.odd(), b.odd());
}

// Mean luminance over the pixels of a block, with its standard error (from the film's own
// variance estimate: the path tracer's samples and, folded in, the splats').
inline testing::Estimate block(const Film& f, int x0, int y0, int w, int h) {
  testing::Estimate e;
  double var = 0;
  for (int y = y0; y < y0 + h; ++y)
    for (int x = x0; x < x0 + w; ++x) {
      e.mean += f.at(x, y).lum_sum() / f.at(x, y).n;
      var += f.at(x, y).mean_variance();
    }
  e.mean /= w * h;
  e.stderr_ = std::sqrt(var) / (w * h);
  return e;
}

inline void expect_agree(const testing::Estimate& a, const testing::Estimate& b, const char* what) {
  const double sigma = std::sqrt(a.stderr_ * a.stderr_ + b.stderr_ * b.stderr_);
  EXPECT_LT(std::fabs(a.mean - b.mean), 4.5 * sigma + 1e-4)
      << what << ": " << a.mean << " +- " << a.stderr_ << " against " << b.mean << " +- " << b.stderr_;
}

// Two renders of a caustic scene (32x24) estimate the same image: over the frame and in
// each 8x8 block.
inline void expect_same_image(const Film& a, const Film& b) {
  expect_agree(film_estimate(a), film_estimate(b), "frame");
  for (int by = 0; by < 24; by += 8)
    for (int bx = 0; bx < 32; bx += 8) {
      SCOPED_TRACE("block at " + std::to_string(bx) + ", " + std::to_string(by));
      expect_agree(block(a, bx, by, 8, 8), block(b, bx, by, 8, 8), "block");
    }
}

}  // namespace tessera::testing::caustics
