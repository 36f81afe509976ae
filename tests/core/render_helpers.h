// Helpers shared by the whole-renderer tests.
#pragma once

#include <cmath>
#include <utility>
#include <vector>

#include "core/render/local_renderer.h"
#include "core/scene/scene.h"

namespace tessera::testing {

struct Estimate {
  double mean = 0, stderr_ = 0;  // mean over pixels of the per-pixel means, and its std. error
};

inline Estimate film_estimate(const Film& film) {
  Estimate e;
  double var = 0;
  for (const PixelSums& p : film.pixels()) {
    e.mean += p.lum_sum() / p.n;
    var += p.mean_variance();
  }
  const double n = double(film.pixels().size());
  e.mean /= n;
  e.stderr_ = std::sqrt(var) / n;
  return e;
}

inline RenderResult render(const Scene& scene, RenderSettings s, int threads = 2, int tile = 16) {
  s.tile_size = tile;
  const TileRenderer r(scene, s);
  return render_image(r, threads);
}

// Spheres of material `inner` inside a two-sided emitter of radiance 1 (a sphere of radius
// `enclosure` about the origin), seen from (0, 0, eye_z).
inline Scene furnace_with(std::vector<Sphere> spheres, Material inner, float enclosure = 20, float eye_z = 5,
                          double xfov = 50) {
  Scene s;
  s.materials.push_back(inner);
  Material e;
  e.kind = Material::Kind::kEmission;
  e.radiance = Rgb(1);
  e.two_sided_emission = true;
  s.materials.push_back(e);
  s.spheres = std::move(spheres);
  s.spheres.push_back(Sphere{"enclosure", {0, 0, 0}, enclosure, 1, -1});
  s.camera.present = true;
  s.camera.eye = {0, 0, eye_z};
  s.camera.xfov_deg = xfov;
  s.camera.aspect_ratio = 1;
  s.finalize();
  return s;
}

// A unit sphere of albedo rho inside the emitter: every point on it sees radiance 1 over
// its whole hemisphere, so it reflects exactly rho.
inline Scene furnace(Material inner) { return furnace_with({Sphere{"inner", {0, 0, 0}, 1, 0, -1}}, inner, 10, 4, 40); }

// A unit sphere of material m at the origin and nothing else, seen from (0, 0, 4) with a
// 30-degree view that it fills but for the corners (they see the background).
inline Scene lone_sphere(Material m) {
  Scene s;
  s.materials.push_back(std::move(m));
  s.spheres.push_back(Sphere{"inner", {0, 0, 0}, 1, 0, -1});
  s.camera.present = true;
  s.camera.eye = {0, 0, 4};
  s.camera.xfov_deg = 30;
  s.camera.aspect_ratio = 1;
  s.finalize();
  return s;
}

// glTF's metallic-roughness material (white base colour).
inline Material pbr_material(float metallic, float roughness, float transmission = 0, bool thin = true) {
  Material m;
  m.kind = Material::Kind::kPbr;
  m.reflectance = Rgb(1.0f);
  m.metallic = metallic;
  m.roughness = roughness;
  m.alpha = roughness * roughness;
  m.transmission = transmission;
  m.thin = thin;
  return m;
}

// A 2x1 texture, red then blue, clamped: on a quad [-1, 1]^2 mapped u = (x + 1) / 2, x < 0
// is red and x > 0 blue.
inline Texture red_blue_texture() {
  Texture t;
  t.width = 2;
  t.height = 1;
  t.texels = {Rgb(1.0f, 0.0f, 0.0f), Rgb(0.0f, 0.0f, 1.0f)};
  t.wrap_s = t.wrap_t = Texture::Wrap::kClamp;
  return t;
}

inline RenderSettings furnace_settings() {
  RenderSettings s;
  s.camera.framing = Framing::kFile;
  s.camera.width = s.camera.height = 24;
  s.spp = 64;
  s.max_depth = 100;
  s.light_samples = 2;
  return s;
}

// The same scene scaled by `s` about the origin, then moved by `t`.
inline Scene transformed(Scene scene, float s, Vec3 t) {
  for (Mesh& m : scene.meshes)
    for (Vec3& p : m.positions) p = p * s + t;
  for (Sphere& sp : scene.spheres) {
    sp.center = sp.center * s + t;
    sp.radius *= s;
  }
  for (Light& l : scene.lights) {
    l.position = l.position * s + t;
    l.edge_x = l.edge_x * s;
    l.edge_y = l.edge_y * s;
    l.area *= s * s;
  }
  return scene;
}

}  // namespace tessera::testing
