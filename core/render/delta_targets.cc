#include "core/render/delta_targets.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/math/float_math.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

// 1 - cos of the half-angle of the cone a sphere of radius r subtends at distance d > r:
// 1 - sqrt(1 - x), x = r^2 / d^2, written without the cancellation for small cones.
float one_minus_cos(float r, float d) {
  const float x = std::min(1.0f, (r * r) / (d * d));
  return x / (1 + std::sqrt(1 - x));
}

// A target of centre c and radius r, with a margin for the rounding of positions, centres
// and the cone test.
DeltaTargets::Target around(Vec3 c, float r) { return {c, r * (1 + 1e-4f) + 1e-6f * (max_component(abs(c)) + r)}; }

DeltaTargets::Target bound(const Bounds& b) { return around(b.center(), 0.5f * length(b.diagonal())); }

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
  materials_.resize(scene.materials.size());
  for (size_t i = 0; i < scene.materials.size(); ++i) materials_[i] = has_delta_lobe(scene.materials[i]);
  Bounds all;  // every shape together: the one target past kMaxTargets
  for (const Sphere& s : scene.spheres) {
    if (!aims_at(s.material)) continue;
    targets_.push_back(around(s.center, s.radius));  // exact: a sphere bounds itself
    all.extend(s.center - Vec3{s.radius, s.radius, s.radius});
    all.extend(s.center + Vec3{s.radius, s.radius, s.radius});
  }
  auto add = [&](const Bounds& b) {
    targets_.push_back(bound(b));
    all.extend(b.lo);
    all.extend(b.hi);
  };
  std::vector<Bounds> object(scene.meshes.size());  // each mesh's own, object space
  for (size_t i = 0; i < scene.meshes.size(); ++i) {
    const Mesh& m = scene.meshes[i];
    if (!aims_at(m.material)) continue;
    for (const uint32_t v : m.indices) object[i].extend(m.positions[v]);
    if (!m.instanced && !object[i].empty()) add(object[i]);
  }
  for (const Instance& in : scene.instances) {
    const Bounds& o = object[in.mesh];
    if (o.empty()) continue;
    Bounds b;
    for (int k = 0; k < 8; ++k)
      b.extend(in.point(Vec3{k & 1 ? o.hi.x : o.lo.x, k & 2 ? o.hi.y : o.lo.y, k & 4 ? o.hi.z : o.lo.z}));
    add(b);
  }
  if (targets_.size() > kMaxTargets) targets_ = {bound(all)};
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
    float sn, cs;
    fm::sincos(2 * kPi * u.y, &sn, &cs);
    dir = normalize(Frame(to / d).to_world(Vec3{sin_t * cs, sin_t * sn, cos_t}));
  }
  *pdf = pdf_with(p, dir, k);
  return dir;
}

namespace {
// Whether unit `dir` is within the cone of directions from a point toward a sphere of
// `radius` whose centre is `to` away (|to| = d, 1 - cos of the cone's half-angle = omc).
// For a narrow cone (a target more than about 700 radii away) 1 - omc rounds to 1 and the
// cosine test became a coin toss over a region far wider than the cone (a distant light's
// light tracing 2.9% dark with two targets): there the distance of the sphere's centre
// from the ray's line, |dir x to| <= radius, decides. Elsewhere the cosine test, as ever.
bool in_cone(Vec3 dir, Vec3 to, float d, float radius, float omc) {
  if (omc >= 0x1p-10f) return dot(dir, to) >= (1 - omc) * d;
  const Vec3 c = cross(dir, to);
  return dot(dir, to) > 0 && dot(c, c) <= radius * radius;
}
}  // namespace

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
    if (k == sure || in_cone(dir, to, d, t.radius, omc)) sum += 1 / (2 * kPi * omc);
  }
  return sum / float(targets_.size());
}

}  // namespace tessera
