#include "core/light/lights.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/light/environment.h"
#include "core/math/ulp.h"
#include "core/sampling/warp.h"

namespace tessera {

LightSet::LightSet(const Scene& scene, std::vector<Light> extra) : scene_(scene), lights_(scene.lights) {
  lights_.insert(lights_.end(), extra.begin(), extra.end());
  mesh_data_.resize(lights_.size());
  for (size_t i = 0; i < lights_.size(); ++i) {
    const Light& l = lights_[i];
    if (l.kind == Light::Kind::kAmbient || l.kind == Light::Kind::kEnvironment) infinite_.push_back(i);
    if (l.kind != Light::Kind::kMesh) continue;
    const Mesh& m = scene.meshes[l.shape];
    MeshLightData& d = mesh_data_[i];
    double sum = 0;
    std::vector<double> acc;
    for (size_t t = 0; t < m.triangle_count(); ++t) {
      const Vec3 a = m.positions[m.indices[3 * t]], b = m.positions[m.indices[3 * t + 1]],
                 c = m.positions[m.indices[3 * t + 2]];
      sum += 0.5 * double(length(cross(b - a, c - a)));
      acc.push_back(sum);
    }
    d.area = float(sum);
    d.cdf.resize(acc.size());
    for (size_t t = 0; t < acc.size(); ++t) d.cdf[t] = sum > 0 ? float(acc[t] / sum) : float(t + 1) / acc.size();
  }
}

namespace {

constexpr float kEps = std::numeric_limits<float>::epsilon() * 0.5f;
constexpr float gamma(int n) { return (n * kEps) / (1 - n * kEps); }

// Converts an area sample at q (normal n, `two_sided`) into a solid-angle sample from p.
bool finish_area_sample(Vec3 p, Vec3 q, Vec3 q_err, Vec3 n, float area_pdf, Rgb radiance, bool two_sided,
                        LightSample* out) {
  Vec3 d = q - p;
  const float dist2 = dot(d, d);
  if (!(dist2 > 0)) return false;
  const float dist = std::sqrt(dist2);
  d = d / dist;
  const float cos_l = -dot(n, d);  // > 0 when p is in front of the emitter
  if (cos_l <= 0 && !two_sided) return false;
  const float c = std::fabs(cos_l);
  if (c == 0) return false;
  out->li = radiance;
  out->wi = d;
  out->point = q;
  out->light_n = n;
  out->point_err = q_err;
  out->dist = dist;
  out->pdf = area_pdf * dist2 / c;
  return std::isfinite(out->pdf);
}

}  // namespace

// The points of rect, mesh and sphere lights, one function each so that sample()'s switch
// inlines them (next-event estimation runs it at every vertex).
[[gnu::always_inline]] static inline void rect_point(const Light& l, Vec2 u, LightPoint* out) {
  const Vec3 ex = l.edge_x * (u.x - 0.5f), ey = l.edge_y * (u.y - 0.5f);
  out->q = l.position + (ex + ey);
  // (The floor: a light in a plane through the origin started its light paths a denormal
  // off its own triangles, which Embree's plane test then hit at t = 0: no light paths.)
  const Vec3 err = abs(out->q) * gamma(1) + (abs(ex) + abs(ey)) * gamma(3);
  const float floor = underflow_floor(l.area);  // (|Ng| of the rectangle's triangles)
  out->err = max(err, Vec3{floor, floor, floor});
  out->n = l.normal;
  out->area_pdf = 1 / l.area;
  out->radiance = l.color;
  out->two_sided = false;
}

[[gnu::always_inline]] static inline void sphere_point(const Light& l, const Sphere& s, Vec2 u, LightPoint* out) {
  const Vec3 n = square_to_uniform_sphere(u);
  out->q = s.center + n * s.radius;
  out->err = abs(out->q) * gamma(1) + abs(n * s.radius) * gamma(3);
  out->n = n;
  out->area_pdf = 1 / (4 * kPi * s.radius * s.radius);
  out->radiance = l.color;
  out->two_sided = l.two_sided;
}

[[gnu::always_inline]] inline bool LightSet::mesh_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const {
  const Light& l = lights_[i];
  const MeshLightData& d = mesh_data_[i];
  if (d.cdf.empty() || !(d.area > 0)) return false;
  const size_t t =
      std::min(size_t(std::upper_bound(d.cdf.begin(), d.cdf.end(), u_pick) - d.cdf.begin()), d.cdf.size() - 1);
  const Mesh& m = scene_.meshes[l.shape];
  const Vec3 a = m.positions[m.indices[3 * t]], b = m.positions[m.indices[3 * t + 1]],
             c = m.positions[m.indices[3 * t + 2]];
  const Vec2 bc = square_to_triangle(u);
  const Vec3 e1 = (b - a) * bc.x, e2 = (c - a) * bc.y;
  out->q = a + (e1 + e2);  // as make_surface_point: exact edges far from the origin
  const Vec3 n = cross(b - a, c - a);
  const float len = length(n);
  if (!(len > 0)) return false;
  const float floor = underflow_floor(len);  // (as rect_point's)
  out->err = max(abs(out->q) * gamma(1) + (abs(e1) + abs(e2)) * gamma(4), Vec3{floor, floor, floor});
  Rgb radiance = l.color;
  const Material& mat = scene_.materials[m.material];
  switch (mat.alpha_mode) {  // where the surface is not there, neither is its light
    case Material::AlphaMode::kOpaque:
      break;
    case Material::AlphaMode::kMask:
      if (!scene_.covered(m, t, bc.x, bc.y, 0)) return false;
      break;
    case Material::AlphaMode::kBlend:
      radiance *= scene_.opacity_at(m, t, bc.x, bc.y);
      break;
  }
  const TextureRef& tex = mat.emissive_texture;
  if (tex.active() && !m.uv_set(tex.set).empty())  // glTF emissiveTexture
    radiance *= scene_.textures[size_t(tex.index)].sample(tex.map(m.uv_at(t, bc.x, bc.y, tex.set)));
  out->n = n / len;
  out->area_pdf = 1 / d.area;
  out->radiance = radiance;
  out->two_sided = l.two_sided;
  return true;
}

bool LightSet::area_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const {
  const Light& l = lights_[i];
  switch (l.kind) {
    case Light::Kind::kRect:
      rect_point(l, u, out);
      return true;
    case Light::Kind::kMesh:
      return mesh_point(i, u_pick, u, out);
    case Light::Kind::kSphere:
      sphere_point(l, scene_.spheres[l.shape], u, out);
      return true;
    default:
      return false;
  }
}

bool LightSet::sample(size_t i, Vec3 p, float u_pick, Vec2 u, LightSample* out) const {
  const Light& l = lights_[i];
  switch (l.kind) {
    case Light::Kind::kRect: {
      LightPoint a;
      rect_point(l, u, &a);
      return finish_area_sample(p, a.q, a.err, a.n, a.area_pdf, a.radiance, a.two_sided, out);
    }
    case Light::Kind::kMesh: {
      LightPoint a;
      return mesh_point(i, u_pick, u, &a) &&
             finish_area_sample(p, a.q, a.err, a.n, a.area_pdf, a.radiance, a.two_sided, out);
    }
    case Light::Kind::kSphere: {
      LightPoint a;
      sphere_point(l, scene_.spheres[l.shape], u, &a);
      return finish_area_sample(p, a.q, a.err, a.n, a.area_pdf, a.radiance, a.two_sided, out);
    }
    case Light::Kind::kPoint: {
      Vec3 d = l.position - p;
      const float dist = length(d);
      if (!(dist > 0)) return false;
      out->wi = d / dist;
      out->dist = dist;
      out->point = l.position;
      out->pdf = 1;
      out->li = l.color / (l.att_constant + l.att_linear * dist + l.att_quadratic * dist * dist);
      return true;
    }
    case Light::Kind::kSpot: {
      Vec3 d = l.position - p;
      const float dist = length(d);
      if (!(dist > 0)) return false;
      out->wi = d / dist;
      // KHR_lights_punctual's falloff: squared linear ramp in cos between the cones.
      const float cd = dot(l.direction, -out->wi);
      const float scale = 1 / std::max(0.001f, l.cos_inner - l.cos_outer);
      float a = std::clamp((cd - l.cos_outer) * scale, 0.0f, 1.0f);
      a *= a;
      if (a <= 0) return false;
      out->dist = dist;
      out->point = l.position;
      out->pdf = 1;
      out->li = l.color * (a / (l.att_constant + l.att_linear * dist + l.att_quadratic * dist * dist));
      return true;
    }
    case Light::Kind::kDirectional: {
      out->wi = l.direction;
      out->dist = std::numeric_limits<float>::infinity();
      out->pdf = 1;
      out->li = l.color;
      return true;
    }
    case Light::Kind::kAmbient: {
      const Vec3 h = square_to_uniform_hemisphere(u);  // about +z; +Y is up in the world
      out->wi = {h.x, h.z, h.y};
      out->dist = std::numeric_limits<float>::infinity();
      out->pdf = kUniformHemispherePdf;
      out->li = l.color;
      return true;
    }
    case Light::Kind::kEnvironment: {
      out->dist = std::numeric_limits<float>::infinity();
      if (l.map) {
        if (!l.map->sample(u, &out->wi, &out->pdf)) return false;
        out->li = l.color * l.map->radiance(out->wi);
        return true;
      }
      out->wi = square_to_uniform_sphere(u);
      out->pdf = kUniformSpherePdf;
      out->li = l.color;
      return true;
    }
  }
  return false;
}

float LightSet::pdf_area_hit(size_t i, Vec3 p, Vec3 q, Vec3 nq, float dist) const {
  const Light& l = lights_[i];
  float area_pdf = 0;
  switch (l.kind) {
    case Light::Kind::kRect:
      area_pdf = 1 / l.area;
      break;
    case Light::Kind::kMesh:
      area_pdf = mesh_data_[i].area > 0 ? 1 / mesh_data_[i].area : 0;
      break;
    case Light::Kind::kSphere: {
      const float r = scene_.spheres[l.shape].radius;
      area_pdf = 1 / (4 * kPi * r * r);
      break;
    }
    default:
      return 0;
  }
  const Vec3 d = (q - p) / dist;
  const float c = std::fabs(dot(nq, d));
  return c > 0 ? area_pdf * dist * dist / c : 0;
}

Rgb LightSet::infinite_le(size_t i, Vec3 dir) const {
  const Light& l = lights_[i];
  if (l.kind == Light::Kind::kEnvironment) return l.map ? l.color * l.map->radiance(dir) : l.color;
  return (l.kind == Light::Kind::kAmbient && dir.y > 0) ? l.color : Rgb(0);
}

float LightSet::infinite_pdf(size_t i, Vec3 dir) const {
  const Light& l = lights_[i];
  if (l.kind == Light::Kind::kEnvironment) return l.map ? l.map->pdf(dir) : kUniformSpherePdf;
  return (l.kind == Light::Kind::kAmbient && dir.y > 0) ? kUniformHemispherePdf : 0;
}

}  // namespace tessera
