#include "core/light/lights.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/sampling/warp.h"

namespace tessera {

LightSet::LightSet(const Scene& scene) : scene_(scene), mesh_data_(scene.lights.size()) {
  for (size_t i = 0; i < scene.lights.size(); ++i) {
    const Light& l = scene.lights[i];
    if (l.kind == Light::Kind::kAmbient) infinite_.push_back(i);
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

// The rectangle light as seen from p, for sampling it by solid angle (Urena, Fajardo and
// King 2013, "An Area-Preserving Parametrization for Spherical Rectangles", as in
// pbrt-v4). Computed in double: the setup subtracts nearly equal angles.
struct SphericalRect {
  bool valid = false;  // false: p behind the light, a sheared rectangle, or a solid angle too
                       // small for the parametrization to be accurate (area sampling instead)
  double solid_angle = 0;
  double x0, x1, y0, y1, z0, b0, b1, k;
  Vec3 x, y, z;  // local frame: x, y along the edges, z away from the light's front
};

double angle_between(const double* a, const double* b) {  // unit vectors, stable near 0 and pi
  const double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  auto len = [](double u, double v, double w) { return std::sqrt(u * u + v * v + w * w); };
  return d < 0 ? M_PI - 2 * std::asin(std::min(1.0, len(a[0] + b[0], a[1] + b[1], a[2] + b[2]) / 2))
               : 2 * std::asin(std::min(1.0, len(b[0] - a[0], b[1] - a[1], b[2] - a[2]) / 2));
}

SphericalRect spherical_rect(const Light& l, Vec3 p) {
  SphericalRect r;
  const double exl = length(l.edge_x), eyl = length(l.edge_y);
  r.x = l.edge_x / float(exl);
  r.y = l.edge_y / float(eyl);
  if (std::fabs(dot(r.x, r.y)) > 1e-4f) return r;  // not a rectangle
  r.z = cross(r.x, r.y);
  const Vec3 corner = l.position - l.edge_x * 0.5f - l.edge_y * 0.5f;
  const double dx = double(corner.x) - p.x, dy = double(corner.y) - p.y, dz = double(corner.z) - p.z;
  const auto proj = [&](Vec3 a) { return dx * a.x + dy * a.y + dz * a.z; };
  r.z0 = proj(r.z);
  if (dot(r.z, l.normal) * r.z0 >= 0) return r;  // p is not in front of the emitting face
  if (r.z0 > 0) {
    r.z = -r.z;
    r.z0 = -r.z0;
  }
  r.x0 = proj(r.x);
  r.y0 = proj(r.y);
  r.x1 = r.x0 + exl;
  r.y1 = r.y0 + eyl;
  // Normals of the planes through p and each edge: cross products of corner directions.
  auto unit = [](double a, double b, double c, double* out) {
    const double n = std::sqrt(a * a + b * b + c * c);
    out[0] = a / n, out[1] = b / n, out[2] = c / n;
  };
  double n0[3], n1[3], n2[3], n3[3], m[3];
  unit(0, r.z0, -r.y0, n0);  // cross(v00, v10)
  unit(-r.z0, 0, r.x1, n1);  // cross(v10, v11)
  unit(0, -r.z0, r.y1, n2);  // cross(v11, v01)
  unit(r.z0, 0, -r.x0, n3);  // cross(v01, v00)
  auto neg = [&](const double* a) {
    m[0] = -a[0], m[1] = -a[1], m[2] = -a[2];
    return m;
  };
  const double g0 = angle_between(neg(n0), n1), g1 = angle_between(neg(n1), n2);
  const double g2 = angle_between(neg(n2), n3), g3 = angle_between(neg(n3), n0);
  r.solid_angle = g0 + g1 + g2 + g3 - 2 * M_PI;
  r.b0 = n0[2];
  r.b1 = n2[2];
  r.k = 2 * M_PI - g2 - g3;
  r.valid = std::isfinite(r.solid_angle) && r.solid_angle > 1e-3;
  return r;
}

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

bool LightSet::sample(size_t i, Vec3 p, float u_pick, Vec2 u, LightSample* out) const {
  const Light& l = scene_.lights[i];
  switch (l.kind) {
    case Light::Kind::kRect: {
      const SphericalRect r = spherical_rect(l, p);
      if (r.valid) {  // uniform in solid angle: pdf 1 / solid angle
        const double au = u.x * r.solid_angle + r.k;
        const double fu = (std::cos(au) * r.b0 - r.b1) / std::sin(au);
        double cu = std::copysign(1 / std::sqrt(fu * fu + r.b0 * r.b0), fu);
        cu = std::clamp(cu, -0.9999999, 0.9999999);
        const double xu = std::clamp(-(cu * r.z0) / std::sqrt(std::max(0.0, 1 - cu * cu)), r.x0, r.x1);
        const double dd = std::sqrt(xu * xu + r.z0 * r.z0);
        const double h0 = r.y0 / std::sqrt(dd * dd + r.y0 * r.y0), h1 = r.y1 / std::sqrt(dd * dd + r.y1 * r.y1);
        const double hv = h0 + u.y * (h1 - h0), hv2 = hv * hv;
        const double yv = hv2 < 1 - 1e-9 ? hv * dd / std::sqrt(1 - hv2) : r.y1;
        const Vec3 offset = r.x * float(xu) + r.y * float(yv) + r.z * float(r.z0);
        const Vec3 q = p + offset;
        if (!finish_area_sample(p, q, abs(q) * gamma(2) + abs(offset) * gamma(4), l.normal, 1, l.color, false, out))
          return false;
        out->pdf = float(1 / r.solid_angle);
        return true;
      }
      const Vec3 ex = l.edge_x * (u.x - 0.5f), ey = l.edge_y * (u.y - 0.5f);
      const Vec3 q = l.position + (ex + ey);
      const Vec3 err = abs(q) * gamma(1) + (abs(ex) + abs(ey)) * gamma(3);
      return finish_area_sample(p, q, err, l.normal, 1 / l.area, l.color, false, out);
    }
    case Light::Kind::kMesh: {
      const MeshLightData& d = mesh_data_[i];
      if (d.cdf.empty() || !(d.area > 0)) return false;
      const size_t t =
          std::min(size_t(std::upper_bound(d.cdf.begin(), d.cdf.end(), u_pick) - d.cdf.begin()), d.cdf.size() - 1);
      const Mesh& m = scene_.meshes[l.shape];
      const Vec3 a = m.positions[m.indices[3 * t]], b = m.positions[m.indices[3 * t + 1]],
                 c = m.positions[m.indices[3 * t + 2]];
      const Vec2 bc = square_to_triangle(u);
      const Vec3 e1 = (b - a) * bc.x, e2 = (c - a) * bc.y;
      const Vec3 q = a + (e1 + e2);  // as make_surface_point: exact edges far from the origin
      const Vec3 err = abs(q) * gamma(1) + (abs(e1) + abs(e2)) * gamma(4);
      const Vec3 n = cross(b - a, c - a);
      const float len = length(n);
      if (!(len > 0)) return false;
      return finish_area_sample(p, q, err, n / len, 1 / d.area, l.color, l.two_sided, out);
    }
    case Light::Kind::kSphere: {
      const Sphere& s = scene_.spheres[l.shape];
      const Vec3 n = square_to_uniform_sphere(u);
      const Vec3 q = s.center + n * s.radius;
      const Vec3 err = abs(q) * gamma(1) + abs(n * s.radius) * gamma(3);
      return finish_area_sample(p, q, err, n, 1 / (4 * kPi * s.radius * s.radius), l.color, l.two_sided, out);
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
  }
  return false;
}

float LightSet::pdf_area_hit(size_t i, Vec3 p, Vec3 q, Vec3 nq, float dist) const {
  const Light& l = scene_.lights[i];
  float area_pdf = 0;
  switch (l.kind) {
    case Light::Kind::kRect: {
      const SphericalRect r = spherical_rect(l, p);
      if (r.valid) return float(1 / r.solid_angle);  // as sample() chooses, from the same p
      area_pdf = 1 / l.area;
      break;
    }
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
  const Light& l = scene_.lights[i];
  return (l.kind == Light::Kind::kAmbient && dir.y > 0) ? l.color : Rgb(0);
}

float LightSet::infinite_pdf(size_t i, Vec3 dir) const {
  const Light& l = scene_.lights[i];
  return (l.kind == Light::Kind::kAmbient && dir.y > 0) ? kUniformHemispherePdf : 0;
}

}  // namespace tessera
