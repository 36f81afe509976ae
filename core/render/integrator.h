// Unidirectional path tracer with next-event estimation and multiple importance sampling
// (power heuristic) at every non-delta vertex, Russian roulette, no clamping.
//
// max_depth follows CS184: a path may scatter at most max_depth times, delta bounces
// included; 0 shows only emitters, 1 adds direct lighting (and one specular hop to an
// emitter).
#pragma once

#include <algorithm>
#include <cstdint>
#include <optional>
#include <vector>

#include "core/accel/accel.h"
#include "core/bsdf/bsdf.h"
#include "core/light/lights.h"
#include "core/math/ulp.h"
#include "core/render/aov.h"
#include "core/render/settings.h"
#include "core/sampling/sampler.h"
#include "core/scene/scene.h"

namespace tessera {

struct RayCounters {
  uint64_t rays = 0;         // closest-hit queries
  uint64_t shadow_rays = 0;  // occlusion queries
  uint64_t self_hits = 0;    // continuation rays that hit their own primitive at t ~ 0
  uint64_t splats = 0;       // light paths' connections to the camera added to the frame
  uint64_t split_paths = 0;  // camera paths split behind mirrors or glass (set_specular_splits)
};

// A ray-surface intersection prepared for shading.
struct SurfacePoint {
  Vec3 p;           // rebuilt from barycentrics (triangles) or projected onto the sphere
  Vec3 p_err;       // conservative absolute error bound of p, per component
  Vec3 ng;          // unit geometric normal (winding / outward)
  Vec3 ns;          // unit shading normal, same hemisphere as ng
  Vec2 uv;          // texture coordinates (meshes with TEXCOORD_0)
  Vec2 uv1;         // the second set (meshes with TEXCOORD_1; else uv)
  Rgb color{1.0f};  // vertex colour (meshes with COLOR_0), when `colored`
  bool colored = false;
  uint32_t material = 0;
  int32_t light = -1;
};

SurfacePoint make_surface_point(const Scene& scene, const Ray& ray, const Hit& hit);
// Turns sp->ns by material m's normal map (glTF tangent space): mapped_normal of its
// normalTexture.
void apply_normal_map(const Scene& scene, const Material& m, const Hit& hit, SurfacePoint* sp);
// sp.ns turned by the tangent-space normal map `ref` (x `scale` in x and y): the frame is
// the mesh's TANGENTs where it has them (B = cross(N, T) x sign), else the triangle's
// texture-space derivatives (T along dp/du, B toward image up). sp.ns where the map or
// frame degenerates or would turn the normal under the surface.
Vec3 mapped_normal(const Scene& scene, const TextureRef& ref, float scale, const Hit& hit, const SurfacePoint& sp);
// The material at a hit as shading sees it: the scene's, or where textures or vertex
// colours apply, a copy in *textured with them applied (its normal map turning sp->ns,
// and the coat's own mapped normal, world space, in *coat_ns). Shared by the path and
// light tracers so that both see the same surface.
// (Inline: in the bounce loop, where it was written before the light tracer shared it.)
[[gnu::always_inline]] inline const Material& material_at(const Scene& scene, const Hit& hit, SurfacePoint* sp,
                                                          std::optional<Material>* textured,
                                                          std::optional<Vec3>* coat_ns) {
  const Material* mp = &scene.materials[sp->material];
  // Only textured or vertex-coloured materials pay for a copy.
  textured->reset();
  if (mp->has_textures()) {
    textured->emplace(scene.textured(*mp, sp->uv, sp->uv1));
    mp = &**textured;
    // The coat's normal from the surface's own (the base's map does not turn it).
    if (mp->clearcoat_normal_texture.active() && mp->clearcoat > 0)
      *coat_ns = mapped_normal(scene, mp->clearcoat_normal_texture, mp->clearcoat_normal_scale, hit, *sp);
    if (mp->normal_texture.active()) apply_normal_map(scene, *mp, hit, sp);
  }
  if (sp->colored && mp->kind == Material::Kind::kPbr) {  // glTF COLOR_0 multiplies the base colour
    if (!*textured) textured->emplace(*mp);
    (*textured)->reflectance = (*textured)->reflectance * sp->color;
    mp = &**textured;
  }
  return *mp;
}
// A point p with error bound p_err on a surface with normal n, pushed off the surface along
// n (to the side w points to) by the error bound, so that a ray between it and elsewhere
// can neither start behind the surface nor hit it again.
inline Vec3 offset_point(Vec3 p, Vec3 p_err, Vec3 n, Vec3 w) {
  constexpr float kOffsetSafety = 2.0f;  // margin for Embree's own rounding in its plane test
  const float d = (std::fabs(n.x) * p_err.x + std::fabs(n.y) * p_err.y + std::fabs(n.z) * p_err.z) * kOffsetSafety;
  const Vec3 side = dot(w, n) < 0 ? -n : n;
  // Then one ulp further in every component the normal has: where the bound is zero (a
  // point on a coordinate plane, exact) the ray would otherwise start on the surface, where
  // Embree reports t = 0. (Inline, per component: this runs three times a vertex.)
  return {step_toward(p.x + side.x * d, side.x), step_toward(p.y + side.y * d, side.y),
          step_toward(p.z + side.z * d, side.z)};
}
inline Vec3 offset_ray_origin(const SurfacePoint& sp, Vec3 w) { return offset_point(sp.p, sp.p_err, sp.ng, w); }

class Integrator {
 public:
  Integrator(const Scene& scene, const Accel& accel, const LightSet& lights, const RenderSettings& settings);
  // The radiance along a camera ray; with `first`, also what its first hit saw (AOVs: no
  // work at all without).
  Rgb radiance(Ray ray, Sampler& sampler, RayCounters& counters, FirstHit* first = nullptr) const;
  // Leaves the caustic paths that end on these lights (a flag per LightSet index) to the
  // light tracer: a path whose first hit scatters by a non-delta lobe and whose last
  // scattering before reaching one of them is a delta lobe adds nothing here. Empty: none.
  // Only paths with at most `smooth` non-delta vertices (LightTracer::kMaxSmoothVertices),
  // and whose last scattering is at a material light paths aim at (`materials`, a flag per
  // Scene::materials index: LightTracer::target_materials).
  void leave_to_light_tracer(std::vector<uint8_t> lights, int smooth, std::vector<uint8_t> materials) {
    light_traced_ = std::move(lights);
    light_traced_smooth_ = smooth;
    light_traced_materials_ = std::move(materials);
  }
  // Paths seen through mirrors and glass (camera -> delta ... -> smooth): `n` independent
  // continuations from their first smooth vertex, averaged, each with its own sampler
  // dimensions. With the light tracer on, those pixels are the only ones it cannot help
  // (a light path cannot reach the camera through a delta lobe) and the rest of the image
  // is much less noisy than they are (docs/light-tracing.md). 1: none.
  void set_specular_splits(int n) { splits_ = std::max(1, n); }

 private:
  // A path's state between vertices.
  struct PathState {
    Rgb beta{1.0f};
    bool specular = true;       // the previous vertex was the camera or a delta lobe
    bool first_smooth = false;  // the first hit scattered by a non-delta lobe
    int smooth_vertices = 0;    // vertices so far that scattered by a non-delta lobe
    bool at_target = false;     // the previous vertex's material is a light tracer's target
    int depth = 0;
    float prev_pdf = 0, eta_scale = 1;
    Vec3 prev_p, prev_ng;  // the previous vertex's point (MIS) and geometric normal
    Hit prev_hit;
  };
  // Sampler dimensions apart between split continuations (a path uses far fewer).
  static constexpr uint32_t kSplitDimensions = 1u << 20;
  // The path from `ray` on, its state in s; with kSplit, splits at its first smooth vertex
  // behind a delta one (a template: the path tracer without splits runs no split code).
  template <bool kSplit>
  Rgb walk(Ray ray, PathState s, Sampler& sampler, RayCounters& counters, FirstHit* first) const;
  // BSDF sampling at sp, then Russian roulette: the next ray in *ray, or false where the
  // path ends.
  // lobes: bsdf_lobes(m, wo), computed once a vertex.
  bool scatter(const SurfacePoint& sp, const Material& m, const BsdfLobes& lobes, const Frame& frame, Vec3 wo, Vec3 ng,
               bool dielectric, PathState& s, Sampler& sampler, Ray* ray) const;
  Rgb direct(const SurfacePoint& sp, const Material& m, const BsdfLobes& lobes, const Frame& frame, Vec3 wo, Vec3 ng,
             Sampler& sampler, RayCounters& counters) const;

  const Scene& scene_;
  const Accel& accel_;
  const LightSet& lights_;
  int max_depth_;
  int light_samples_;
  bool nee_ = true, mis_ = true;
  std::vector<uint8_t> light_traced_;
  int light_traced_smooth_ = 0;
  std::vector<uint8_t> light_traced_materials_;
  int splits_ = 1;
};

}  // namespace tessera
