#include "core/render/integrator.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

#include "core/bsdf/bsdf.h"
#include "core/math/float_math.h"
#include "core/math/ulp.h"
#include "core/sampling/warp.h"

namespace tessera {
namespace {

constexpr float kMachineEps = std::numeric_limits<float>::epsilon() * 0.5f;
constexpr float gamma(int n) { return (n * kMachineEps) / (1 - n * kMachineEps); }
// The double-precision sphere test's error in the sign of |o - c|^2 - r^2, relative to r,
// with a wide margin (2^-40 against about 2^-51).
constexpr float kSphereTestError = 0x1p-40f;
// Russian roulette leaves paths whose throughput is above this alone (see radiance()).
constexpr float kRouletteFloor = 0.25f;

Vec3 splat(float v) { return {v, v, v}; }

// The normal map's frame from the triangle itself (pbrt's Triangle::InteractionFromIntersection:
// dp/du and dp/dv of its texture coordinates `uvs`), where the file gives no tangents:
// t along dp/du made orthogonal to n, b = cross(n, t) turned to image "up" (v decreasing,
// glTF's convention) for an unmirrored mapping. False where the mapping degenerates.
bool triangle_tangents(const Mesh& mesh, const std::vector<Vec2>& uvs, const Instance* in, uint32_t i0, uint32_t i1,
                       uint32_t i2, Vec3 n, Vec3* t, Vec3* b) {
  const Vec2 uv0 = uvs[i0], uv1 = uvs[i1], uv2 = uvs[i2];
  const Vec2 d02{uv0.x - uv2.x, uv0.y - uv2.y}, d12{uv1.x - uv2.x, uv1.y - uv2.y};
  const Vec3 p02 = mesh.positions[i0] - mesh.positions[i2], p12 = mesh.positions[i1] - mesh.positions[i2];
  const float det = d02.x * d12.y - d02.y * d12.x;
  if (!(std::fabs(det) > 1e-12f)) return false;
  Vec3 dpdu = (p02 * d12.y - p12 * d02.y) / det, dpdv = (p12 * d02.x - p02 * d12.x) / det;
  if (in) {  // into the world
    dpdu = in->vector(dpdu);
    dpdv = in->vector(dpdv);
  }
  *t = dpdu - n * dot(n, dpdu);
  const float tl = length(*t);
  if (!(tl > 0) || !std::isfinite(tl)) return false;
  *t = *t / tl;
  *b = cross(n, *t);
  if (dot(*b, dpdv) > 0) *b = -*b;
  return true;
}

}  // namespace

SurfacePoint make_surface_point(const Scene& scene, const Ray& ray, const Hit& hit) {
  SurfacePoint sp;
  if (hit.is_sphere) {
    const Sphere& s = scene.spheres[hit.shape];
    // Project the hit onto the sphere in double: error is then a few ulps of |p|.
    const double px = double(ray.o.x) + double(ray.d.x) * hit.t - s.center.x;
    const double py = double(ray.o.y) + double(ray.d.y) * hit.t - s.center.y;
    const double pz = double(ray.o.z) + double(ray.d.z) * hit.t - s.center.z;
    const double len = std::sqrt(px * px + py * py + pz * pz);
    const double k = len > 0 ? s.radius / len : 0;
    sp.ng = len > 0 ? Vec3{float(px / len), float(py / len), float(pz / len)} : Vec3{0, 0, 1};
    sp.p = Vec3{float(s.center.x + px * k), float(s.center.y + py * k), float(s.center.z + pz * k)};
    // Computed in double: the only error left is rounding each coordinate to float. The
    // intersection test (double) is exact to about 2^-50 of the radius: where |p| is tiny
    // (a sphere touching the origin) the rounding bound vanishes and that error is left.
    sp.p_err = max(abs(sp.p) * gamma(2), splat(s.radius * kSphereTestError));
    sp.ns = sp.ng;
    sp.material = s.material;
    sp.light = s.light;
    return sp;
  }
  const Mesh& m = scene.meshes[hit.shape];
  const Instance* in = hit.instance >= 0 ? &scene.instances[size_t(hit.instance)] : nullptr;
  const uint32_t i0 = m.indices[3 * hit.prim], i1 = m.indices[3 * hit.prim + 1], i2 = m.indices[3 * hit.prim + 2];
  Vec3 p0 = m.positions[i0], p1 = m.positions[i1], p2 = m.positions[i2];
  // An instance's hit: the triangle placed in the world (each vertex rounded once).
  const float obj_len = in ? length(cross(p1 - p0, p2 - p0)) : 0;
  if (in) p0 = in->point(p0), p1 = in->point(p1), p2 = in->point(p2);
  const float b1 = hit.u, b2 = hit.v, b0 = 1 - b1 - b2;
  // p0 + b1 e1 + b2 e2 rather than b0 p0 + b1 p1 + b2 p2: far from the origin the edges
  // of a small triangle subtract exactly, so the error is one rounding of |p| plus the
  // (small) error of the edge terms, not three roundings of terms as large as |p|.
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  sp.p = p0 + (e1 * b1 + e2 * b2);
  sp.p_err = abs(sp.p) * gamma(1) + (abs(e1 * b1) + abs(e2 * b2)) * gamma(4);
  Vec3 ng = cross(p1 - p0, p2 - p0);
  if (in && in->mirrored) ng = -ng;  // the authored front face
  float len = length(ng);
  if (!(len > 0) || !std::isfinite(len)) {  // degenerate triangle: Embree's own normal
    ng = in ? in->normal_to_world(hit.ng) : hit.ng;
    len = length(ng);
  }
  sp.ng = len > 0 ? ng / len : Vec3{0, 0, 1};
  if (in) {
    // The vertices' rounding into the world, and Embree taking the next ray's origin into
    // object space and its plane test there (the floor below, in object units).
    sp.p_err = sp.p_err + max(max(abs(p0), abs(p1)), abs(p2)) * gamma(1) + in->round_trip_error(sp.p) +
               in->abs_vector(splat(underflow_floor(obj_len)));
  }
  // The intersector's absolute error. The bound above is relative (pbrt-v4's model,
  // |fl(x) - x| <= eps |x|), which fails where products underflow: Embree's plane test
  // computes T = 2 dot(v0 - o, Ng) with |Ng| = len, so an origin 1 ulp off a plane through
  // 0 (a denormal) times len < 1 rounds to T = 0, a hit at t = 0 (Embree accepts t >=
  // tnear). The floor keeps |Ng| x offset above FLT_MIN (and the offset itself normal, for
  // flush-to-zero), whatever the triangle's size; at any other position the relative
  // bound is larger by orders of magnitude, so nothing else moves (docs/ray-offsets.md).
  sp.p_err = max(sp.p_err, splat(underflow_floor(len)));
  Vec3 ns = m.normals[i0] * b0 + m.normals[i1] * b1 + m.normals[i2] * b2;
  if (in) ns = in->normal_to_world(ns);
  const float ns_len = length(ns);
  sp.ns = ns_len > 0 ? ns / ns_len : sp.ng;
  sp.ns = face_forward(sp.ns, sp.ng);
  if (!m.uvs.empty()) sp.uv = sp.uv1 = m.uv_at(hit.prim, b1, b2);
  if (!m.uvs1.empty()) sp.uv1 = m.uv_at(hit.prim, b1, b2, 1);
  if (!m.colors.empty()) {
    sp.color = m.colors[i0] * b0 + m.colors[i1] * b1 + m.colors[i2] * b2;
    sp.colored = true;
  }
  sp.material = m.material;
  sp.light = m.light;
  return sp;
}

void apply_normal_map(const Scene& scene, const Material& m, const Hit& hit, SurfacePoint* sp) {
  sp->ns = mapped_normal(scene, m.normal_texture, m.normal_scale, hit, *sp);
}

Vec3 mapped_normal(const Scene& scene, const TextureRef& ref, float scale, const Hit& hit, const SurfacePoint& sp) {
  if (hit.is_sphere) return sp.ns;
  const Mesh& mesh = scene.meshes[hit.shape];
  const std::vector<Vec2>& uvs = mesh.uv_set(ref.set);  // (the map's own set: its tangent frame)
  if (uvs.empty()) return sp.ns;
  const uint32_t i0 = mesh.indices[3 * hit.prim], i1 = mesh.indices[3 * hit.prim + 1],
                 i2 = mesh.indices[3 * hit.prim + 2];
  const Instance* in = hit.instance >= 0 ? &scene.instances[size_t(hit.instance)] : nullptr;
  const Vec3 n = sp.ns;
  Vec3 t, b;
  if (!mesh.tangents.empty()) {
    // The file's tangents (MikkTSpace, as its author baked the map against), interpolated
    // and made orthogonal to the shading normal; glTF's bitangent cross(N, T) x sign.
    const float b1 = hit.u, b2 = hit.v;
    t = mesh.tangents[i0].t * (1 - b1 - b2) + mesh.tangents[i1].t * b1 + mesh.tangents[i2].t * b2;
    if (in) t = in->vector(t);
    t = t - n * dot(n, t);
    const float tl = length(t);
    if (!(tl > 0) || !std::isfinite(tl)) return sp.ns;
    t = t / tl;
    b = cross(n, t) * (in && in->mirrored ? -mesh.tangents[i0].sign : mesh.tangents[i0].sign);
  } else if (!triangle_tangents(mesh, uvs, in, i0, i1, i2, n, &t, &b)) {
    return sp.ns;
  }
  const Rgb c = scene.textures[size_t(ref.index)].sample(ref.map(ref.set ? sp.uv1 : sp.uv));
  const float x = (2 * c.r - 1) * scale, y = (2 * c.g - 1) * scale, z = 2 * c.b - 1;
  Vec3 mapped = t * x + b * y + n * z;
  const float len = length(mapped);
  if (!(len > 0) || !std::isfinite(len)) return sp.ns;
  mapped = mapped / len;
  if (dot(mapped, sp.ng) <= 0) return sp.ns;  // a map that turns the normal under the surface: ignore it here
  return mapped;
}

Integrator::Integrator(const Scene& scene, const Accel& accel, const LightSet& lights, const RenderSettings& s)
    : scene_(scene),
      accel_(accel),
      lights_(lights),
      max_depth_(s.max_depth),
      light_samples_(std::max(1, s.light_samples)),
      nee_(s.nee),
      mis_(s.mis) {}

[[gnu::always_inline]] inline Rgb Integrator::direct(const SurfacePoint& sp, const Material& m, const BsdfLobes& lobes,
                                                     const Frame& frame, Vec3 wo, Vec3 ng, Sampler& sampler,
                                                     RayCounters& counters) const {
  Rgb sum(0);
  const bool pbr = m.kind == Material::Kind::kPbr;
  for (size_t i = 0; i < lights_.size(); ++i) {
    const Light& light = lights_.light(i);
    const int n = light.is_delta() ? 1 : light_samples_;
    Rgb acc(0);
    for (int j = 0; j < n; ++j) {
      const float u_pick = light.kind == Light::Kind::kMesh ? sampler.next_1d() : 0.0f;
      const Vec2 u = sampler.next_2d();
      LightSample ls;
      if (!lights_.sample(i, sp.p, u_pick, u, &ls) || ls.li.is_black()) continue;
      // Below the geometric surface: no leaks (a dielectric transmits there).
      if (!m.is_dielectric() && dot(ls.wi, ng) <= 0) continue;
      const Vec3 wi = frame.to_local(ls.wi);
      // The density only where MIS weighs the sample, with f in one pass for glTF PBR.
      const bool weigh = !light.is_delta() && mis_;
      float bsdf_density = 0;
      const Rgb f = weigh && pbr ? bsdf_eval_pdf(m, lobes, wo, wi, &bsdf_density) : bsdf_eval(m, wo, wi);
      if (f.is_black()) continue;
      Ray shadow;
      shadow.o = offset_ray_origin(sp, ls.wi);
      shadow.d = ls.wi;
      shadow.tmin = 0;
      shadow.tmax = std::numeric_limits<float>::infinity();
      if (!std::isinf(ls.dist)) {
        // Both ends leave their surfaces (pbrt's SpawnRayTo): the light point is moved
        // off the emitter toward p by its own error bound, so the ray cannot reach it.
        const Vec3 target = ls.light_n == Vec3{} ? ls.point : offset_point(ls.point, ls.point_err, ls.light_n, -ls.wi);
        shadow.tmax = length(target - shadow.o) * (1 - 1e-5f);
      }
      ++counters.shadow_rays;
      if (accel_.occluded(shadow)) continue;
      Rgb c = f * ls.li * (std::fabs(wi.z) / ls.pdf);
      if (weigh) c *= power_heuristic(float(n), ls.pdf, 1, pbr ? bsdf_density : bsdf_pdf(m, lobes, wo, wi));
      acc += c;
    }
    sum += acc / float(n);
  }
  return sum;
}

namespace {

void record_first_hit(const Material& m, const SurfacePoint& sp, const Ray& ray, FirstHit* first) {
  first->hit = true;
  first->distance = length(sp.p - ray.o);
  first->normal = dot(sp.ns, ray.d) > 0 ? -sp.ns : sp.ns;
  first->albedo = m.kind == Material::Kind::kEmission
                      ? (m.radiance.max() > 0 ? m.radiance * (1.0f / m.radiance.max()) : Rgb(0))
                      : m.reflectance;
  first->material = sp.material;
}

}  // namespace

[[gnu::always_inline]] inline bool Integrator::scatter(const SurfacePoint& sp, const Material& m,
                                                       const BsdfLobes& lobes, const Frame& frame, Vec3 wo, Vec3 ng,
                                                       bool dielectric, PathState& s, Sampler& sampler,
                                                       Ray* ray) const {
  const float u1 = sampler.next_1d();
  const Vec2 u2 = sampler.next_2d();
  BsdfSample bs;
  if (!bsdf_sample(m, lobes, wo, u1, u2, &bs)) return false;
  const Vec3 wi = frame.to_world(bs.wi);
  // A shading normal can send a reflection below the true surface: drop it.
  if (!dielectric && dot(wi, ng) <= 0) return false;
  s.beta *= bs.weight;
  if (s.beta.is_black() || !s.beta.is_finite()) return false;
  s.specular = bs.delta;
  if (s.depth == 0) s.first_smooth = !bs.delta;
  s.smooth_vertices += !bs.delta;
  s.at_target = !light_traced_materials_.empty() && light_traced_materials_[sp.material];
  s.prev_pdf = bs.pdf;
  s.prev_p = sp.p;
  s.prev_ng = sp.ng;
  s.eta_scale *= bs.etap * bs.etap;

  if (s.depth >= 2) {  // Russian roulette on the throughput, undoing the eta^2 scaling
    // A weight window: paths carrying at least kRouletteFloor of the camera's weight go
    // on; below it a path survives with probability throughput / kRouletteFloor, so a
    // survivor's weight is raised back to the floor and never above it. The textbook
    // survival = throughput (floor 1) raises weak paths up to weight 1: on the CS184
    // boxes that doubled the relMSE at 16 spp for 25% less time (docs/performance.md).
    const float rr = (s.beta * s.eta_scale).max() / kRouletteFloor;
    if (rr < 1) {
      const float q = std::max(0.0f, 1 - rr);
      if (sampler.next_1d() < q) return false;
      s.beta = s.beta / (1 - q);
    }
  }
  ray->o = offset_ray_origin(sp, wi);
  ray->d = wi;
  ray->tmin = 0;
  ray->tmax = std::numeric_limits<float>::infinity();
  return true;
}

Rgb Integrator::radiance(Ray ray, Sampler& sampler, RayCounters& counters, FirstHit* first) const {
  return splits_ > 1 ? walk<true>(ray, PathState{}, sampler, counters, first)
                     : walk<false>(ray, PathState{}, sampler, counters, first);
}

template <bool kSplit>
Rgb Integrator::walk(Ray ray, PathState s, Sampler& sampler, RayCounters& counters, FirstHit* first) const {
  Rgb L(0);
  const float n_light = float(light_samples_);
  // A textured or vertex-coloured hit's material (a copy), empty at every other hit. Made
  // once a thread: g++ 12 zero-fills an optional<Material>'s 616 bytes where it is
  // constructed (4% of the kernel's instructions inside the loop; once a walk, a `rep stos`
  // that was 1.3% of the time). Each instantiation has its own: walk<true> calls
  // walk<false> while its own may be in use.
  thread_local std::optional<Material> textured;
  textured.reset();
  for (;; ++s.depth) {
    Hit hit;
    ++counters.rays;
    if (!accel_.intersect(ray, &hit)) {
      for (size_t i : lights_.infinite_lights()) {
        const Rgb le = lights_.infinite_le(i, ray.d);
        if (le.is_black()) continue;
        const float w = s.specular || !nee_ ? 1
                        : mis_              ? power_heuristic(1, s.prev_pdf, n_light, lights_.infinite_pdf(i, ray.d))
                                            : 0;  // light sampling alone accounts for it
        L += s.beta * le * w;
      }
      break;
    }
    // A ray leaving a flat triangle can never meet that triangle again: if it does, the
    // origin offset failed (acne). Counted so the stability tests can assert zero.
    // Likewise a ray that left a sphere outward (it is convex).
    if (s.depth > 0 && hit.is_sphere == s.prev_hit.is_sphere && hit.shape == s.prev_hit.shape &&
        hit.instance == s.prev_hit.instance &&
        (hit.is_sphere ? dot(ray.d, s.prev_ng) > 0 : hit.prim == s.prev_hit.prim))
      ++counters.self_hits;
    s.prev_hit = hit;
    SurfacePoint sp = make_surface_point(scene_, ray, hit);
    std::optional<Vec3> coat_ns;
    const Material& m = material_at(scene_, hit, &sp, &textured, &coat_ns);
    if (first && s.depth == 0) record_first_hit(m, sp, ray, first);
    const Vec3 wo_world = -ray.d;
    // Beer-Lambert absorption of a solid glTF volume: the segment just travelled was inside
    // if it leaves through the surface's back (its outward normal faces along the ray).
    if (m.kind == Material::Kind::kPbr && !m.absorption.is_black() && dot(sp.ng, ray.d) > 0) {
      const float t = hit.t;
      s.beta *= Rgb(fm::exp(-m.absorption.r * t), fm::exp(-m.absorption.g * t), fm::exp(-m.absorption.b * t));
    }
    // Emission: an emitter's (the path ends there: it does not reflect) or a glTF surface's
    // own, which adds to its reflection. Only lamps are lights (sp.light), weighted by MIS.
    if (m.emits() || m.kind == Material::Kind::kEmission) {
      if (m.two_sided_emission || dot(sp.ng, wo_world) > 0) {
        float w = 1;
        if (!s.specular && sp.light >= 0 && nee_)
          w = mis_ ? power_heuristic(1, s.prev_pdf, n_light,
                                     lights_.pdf_area_hit(size_t(sp.light), s.prev_p, sp.p, sp.ng, hit.t))
                   : 0;  // light sampling alone accounts for it
        // A path camera -> smooth -> ... -> delta -> a light the light tracer starts from is
        // the light tracer's (light_tracer.h): nothing is counted twice.
        if (!(s.specular && s.first_smooth && s.smooth_vertices <= light_traced_smooth_ && s.at_target &&
              !light_traced_.empty() && sp.light >= 0 && light_traced_[size_t(sp.light)]))
          L += s.beta * m.radiance * w;
      }
      if (m.kind == Material::Kind::kEmission) break;
    }
    if (s.depth >= max_depth_) break;

    // Reflection-only surfaces are two-sided: shade on the side the ray came from.
    // Dielectrics keep the outward normal to know whether the path is inside.
    Vec3 ng = sp.ng, ns = sp.ns;
    const bool dielectric = m.is_dielectric();
    if (!dielectric && dot(ng, wo_world) < 0) {
      ng = -ng;
      ns = -ns;
    }
    const Frame frame(ns);
    const Vec3 wo = frame.to_local(wo_world);
    if (coat_ns)  // (m is *textured here) the coat's normal in the base's frame, turned with it
      textured->coat_normal = frame.to_local(dot(sp.ns, ns) < 0 ? -*coat_ns : *coat_ns);
    const BsdfLobes lobes = bsdf_lobes(m, wo);  // once for the vertex's NEE and its sample
    // The first smooth vertex of a path seen through mirrors or glass: the light tracer
    // cannot reach these pixels (no connection through a delta lobe), so they get
    // splits_ independent continuations, averaged (see set_specular_splits).
    if (kSplit && s.depth > 0 && s.smooth_vertices == 0 && !m.is_delta()) {
      const uint32_t d0 = sampler.dimension();
      ++counters.split_paths;
      Rgb sum(0);
      for (int b = 0; b < splits_; ++b) {
        sampler.set_dimension(d0 + uint32_t(b) * kSplitDimensions);
        PathState c = s;
        Rgb Lb(0);
        if (nee_) Lb += c.beta * direct(sp, m, lobes, frame, wo, ng, sampler, counters);
        Ray next;
        if (scatter(sp, m, lobes, frame, wo, ng, dielectric, c, sampler, &next)) {
          ++c.depth;
          Lb += walk<false>(next, c, sampler, counters, nullptr);
        }
        sum += Lb;
      }
      sampler.set_dimension(d0 + uint32_t(splits_) * kSplitDimensions);
      L += sum / float(splits_);
      break;
    }
    if (nee_ && !m.is_delta()) L += s.beta * direct(sp, m, lobes, frame, wo, ng, sampler, counters);
    if (!scatter(sp, m, lobes, frame, wo, ng, dielectric, s, sampler, &ray)) break;
  }
  return L;
}

}  // namespace tessera
