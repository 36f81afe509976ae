// Light paths' starts: a point on a finite light and a direction leaving it, for the light
// tracer (core/render/light_tracer.h). The point is the one next-event estimation would
// take for the same numbers (LightSet::area_point), so both see the same emitter.
#include <algorithm>
#include <cmath>

#include "core/light/lights.h"
#include "core/sampling/warp.h"

namespace tessera {

bool LightSet::emission_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const {
  const Light& l = lights_[i];
  switch (l.kind) {
    case Light::Kind::kRect:
    case Light::Kind::kMesh:
    case Light::Kind::kSphere:
      return area_point(i, u_pick, u, out) && !out->radiance.is_black() && out->area_pdf > 0;
    case Light::Kind::kPoint:
    case Light::Kind::kSpot:
      *out = LightPoint{l.position, Vec3{}, Vec3{}, l.color, 1, true};
      return !l.color.is_black();
    default:
      return false;
  }
}

Rgb LightSet::emitted_toward(size_t i, const LightPoint& e, Vec3 dir) const {
  const Light& l = lights_[i];
  switch (l.kind) {
    case Light::Kind::kPoint:
      return e.radiance;
    case Light::Kind::kSpot: {  // KHR_lights_punctual's falloff, as sample() has it
      const float cd = dot(l.direction, dir);
      const float scale = 1 / std::max(0.001f, l.cos_inner - l.cos_outer);
      float a = std::clamp((cd - l.cos_outer) * scale, 0.0f, 1.0f);
      return e.radiance * (a * a);
    }
    default: {
      const float c = dot(e.n, dir);
      if (!(c > 0) && !(e.two_sided && c < 0)) return Rgb(0);
      return e.radiance * std::fabs(c);
    }
  }
}

float LightSet::emitted_power(size_t i) const {
  const Light& l = lights_[i];
  const float lum = std::max(0.0f, l.color.luminance());
  switch (l.kind) {
    case Light::Kind::kRect:
      return lum * l.area * kPi;
    case Light::Kind::kMesh:
      return lum * mesh_data_[i].area * kPi * (l.two_sided ? 2 : 1);
    case Light::Kind::kSphere: {
      const float r = scene_.spheres[l.shape].radius;
      return lum * 4 * kPi * r * r * kPi * (l.two_sided ? 2 : 1);
    }
    case Light::Kind::kPoint:
      return lum * 4 * kPi;
    case Light::Kind::kSpot:
      return lum * 2 * kPi * (1 - std::clamp(l.cos_outer, -1.0f, 1.0f));
    default:
      return 0;
  }
}

}  // namespace tessera
