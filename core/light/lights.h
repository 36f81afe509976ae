// Light sampling for next-event estimation, and the densities multiple importance
// sampling needs when a BSDF-sampled ray finds an emitter by itself.
//
//   kind         emits                                   sampled by
//   rect         `color` radiance from its front face    uniform area, pdf d^2/(A cos)
//   mesh         material radiance (one or two sided)    triangle by area, uniform in it
//   sphere       material radiance                       uniform area
//   point        intensity `color` / (c + l d + q d^2)   delta
//   directional  irradiance `color` at normal incidence  delta
//   ambient      `color` radiance from the +Y hemisphere uniform hemisphere, 1/(2 pi)
//   environment  `color` radiance from every direction   uniform sphere, 1/(4 pi)
//                (x an image, core/light/environment.h)  by luminance x sin theta
#pragma once

#include <vector>

#include "core/math/vec.h"
#include "core/scene/scene.h"

namespace tessera {

struct LightSample {
  Rgb li;          // incident radiance (or delta-light equivalent) arriving at p
  Vec3 wi;         // unit direction from p toward the light
  Vec3 point;      // sampled point on the light (finite lights)
  Vec3 light_n;    // light surface normal at `point` (area lights)
  Vec3 point_err;  // absolute error bound of `point`, per component (area lights)
  float dist = 0;  // distance to `point`, infinity for infinite lights
  float pdf = 0;   // solid-angle density, or 1 for delta lights
};

// A point on a finite light: where next-event estimation aims (area lights) and where a
// light path starts (core/light/emission.cc).
struct LightPoint {
  Vec3 q, err;         // the point and its absolute error bound (zero for point and spot lights)
  Vec3 n;              // the emitting surface's unit normal; zero for point and spot lights
  Rgb radiance;        // radiance there (textures and alpha applied), or a point's intensity
  float area_pdf = 1;  // density of the point per unit area (1 for point and spot lights)
  bool two_sided = false;
};

class LightSet {
 public:
  // The scene's lights, then `extra` ones the settings add (an environment).
  explicit LightSet(const Scene& scene, std::vector<Light> extra = {});

  size_t size() const { return lights_.size(); }
  const Light& light(size_t i) const { return lights_[i]; }

  // u_pick chooses the triangle of a mesh light; u the point. Returns false if this
  // sample carries nothing (p behind a one-sided emitter, zero pdf).
  bool sample(size_t i, Vec3 p, float u_pick, Vec2 u, LightSample* out) const;

  // Solid-angle density with which sample() would pick the point q (normal nq) on area
  // light i seen from p at distance dist.
  float pdf_area_hit(size_t i, Vec3 p, Vec3 q, Vec3 nq, float dist) const;

  // A light path's start on finite light i (rect, mesh, sphere, point, spot): the point
  // sample() takes for (u_pick, u). False for infinite lights and where the point carries
  // nothing (core/light/emission.cc).
  bool emission_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const;
  // What leaves that point along unit dir: radiance x |cos| for an area light (zero on a
  // side it does not emit from), intensity (x a spot's falloff) for a point or spot. The
  // light tracer divides it by the densities of the point and the direction.
  Rgb emitted_toward(size_t i, const LightPoint& e, Vec3 dir) const;
  // A light's power as light tracing picks lights by it: luminance x area x pi (x 2 when
  // two-sided) for area lights, x 4 pi (point) or the cone's solid angle (spot); 0 for
  // infinite lights. Textures and alpha are not looked at (only a pick probability).
  float emitted_power(size_t i) const;
  // Radiance of the infinite lights along an escaped ray direction, and each one's pdf.
  bool has_infinite() const { return !infinite_.empty(); }
  const std::vector<size_t>& infinite_lights() const { return infinite_; }
  Rgb infinite_le(size_t i, Vec3 dir) const;
  float infinite_pdf(size_t i, Vec3 dir) const;

 private:
  // The point of area light i (rect, mesh, sphere) that sample() takes for (u_pick, u).
  // False where the point carries nothing (masked out, a degenerate triangle).
  bool area_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const;
  bool mesh_point(size_t i, float u_pick, Vec2 u, LightPoint* out) const;
  struct MeshLightData {
    std::vector<float> cdf;  // cumulative triangle areas, normalised to end at 1
    float area = 0;
  };
  const Scene& scene_;
  std::vector<Light> lights_;
  std::vector<MeshLightData> mesh_data_;  // per light (empty for non-mesh lights)
  std::vector<size_t> infinite_;
};

}  // namespace tessera
