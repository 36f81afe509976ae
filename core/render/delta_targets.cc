#include "core/render/delta_targets.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/sampling/warp.h"

namespace tessera {
namespace {

// 1 - cos of the half-angle of the cone a sphere of radius r subtends at distance d > r:
// 1 - sqrt(1 - x), x = r^2 / d^2, written without the cancellation for small cones.
float one_minus_cos(float r, float d) {
  const float x = std::min(1.0f, (r * r) / (d * d));
  return x / (1 + std::sqrt(1 - x));
}

DeltaTargets::Target bound(const Bounds& b) {
  const Vec3 c = b.center();
  const float r = 0.5f * length(b.diagonal());
  // A margin for the rounding of positions, centres and the cone test.
  const float margin = r * 1e-4f + 1e-6f * (max_component(abs(c)) + r);
  return {c, r + margin};
}

}  // namespace

bool has_delta_lobe(const Material& m) {
  switch (m.kind) {
    case Material::Kind::kMirror:
    case Material::Kind::kGlass:
    case Material::Kind::kRefraction:
      return true;
    case Material::Kind::kPbr:
      return m.alpha < Material::kSmoothAlpha || (m.clearcoat > 0 && m.clearcoat_alpha < Material::kSmoothAlpha);
    default:
      return false;
  }
}

DeltaTargets::DeltaTargets(const Scene& scene) {
  std::vector<Bounds> shapes;
  std::vector<Target> spheres;  // exact: a sphere bounds itself
  for (const Sphere& s : scene.spheres) {
    if (!has_delta_lobe(scene.materials[s.material])) continue;
    spheres.push_back({s.center, s.radius * (1 + 1e-4f) + 1e-6f * (max_component(abs(s.center)) + s.radius)});
    Bounds b;
    b.extend(s.center - Vec3{s.radius, s.radius, s.radius});
    b.extend(s.center + Vec3{s.radius, s.radius, s.radius});
    shapes.push_back(b);
  }
  std::vector<Bounds> object(scene.meshes.size());  // each mesh's own, object space
  for (size_t i = 0; i < scene.meshes.size(); ++i) {
    const Mesh& m = scene.meshes[i];
    if (!has_delta_lobe(scene.materials[m.material])) continue;
    for (const uint32_t v : m.indices) object[i].extend(m.positions[v]);
    if (!m.instanced && !object[i].empty()) shapes.push_back(object[i]);
  }
  for (const Instance& in : scene.instances) {
    const Bounds& o = object[in.mesh];
    if (o.empty()) continue;
    Bounds b;
    for (int k = 0; k < 8; ++k)
      b.extend(in.point(Vec3{k & 1 ? o.hi.x : o.lo.x, k & 2 ? o.hi.y : o.lo.y, k & 4 ? o.hi.z : o.lo.z}));
    shapes.push_back(b);
  }
  if (shapes.size() <= kMaxTargets) {
    targets_ = spheres;
    for (size_t i = spheres.size(); i < shapes.size(); ++i) targets_.push_back(bound(shapes[i]));
    return;
  }
  {
    Bounds all;
    for (const Bounds& b : shapes) {
      all.extend(b.lo);
      all.extend(b.hi);
    }
    targets_ = {bound(all)};
  }
}

Vec3 DeltaTargets::sample(Vec3 p, float u_pick, Vec2 u, float* pdf) const {
  if (targets_.empty()) {
    *pdf = kUniformSpherePdf;
    return square_to_uniform_sphere(u);
  }
  const size_t k = std::min(size_t(u_pick * float(targets_.size())), targets_.size() - 1);
  const Target& t = targets_[k];
  const Vec3 to = t.center - p;
  const float d = length(to);
  Vec3 dir;
  if (!(d > t.radius)) {
    dir = square_to_uniform_sphere(u);
  } else {
    const float omc = one_minus_cos(t.radius, d);
    const float cos_t = 1 - u.x * omc;
    const float sin_t = std::sqrt(std::max(0.0f, u.x * omc * (2 - u.x * omc)));  // sqrt(1 - cos^2), no cancellation
    const float phi = 2 * kPi * u.y;
    dir = normalize(Frame(to / d).to_world(Vec3{sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t}));
  }
  *pdf = pdf_with(p, dir, k);
  return dir;
}

float DeltaTargets::pdf_with(Vec3 p, Vec3 dir, size_t sure) const {
  if (targets_.empty()) return kUniformSpherePdf;
  float sum = 0;
  for (size_t k = 0; k < targets_.size(); ++k) {
    const Target& t = targets_[k];
    const Vec3 to = t.center - p;
    const float d = length(to);
    if (!(d > t.radius)) {
      sum += kUniformSpherePdf;
      continue;
    }
    const float omc = one_minus_cos(t.radius, d);
    if (k == sure || dot(dir, to) >= (1 - omc) * d) sum += 1 / (2 * kPi * omc);
  }
  return sum / float(targets_.size());
}

}  // namespace tessera
