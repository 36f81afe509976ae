#include "core/render/light_tracer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "core/bsdf/bsdf.h"
#include "core/math/float_math.h"

namespace tessera {
namespace {

// Light paths draw from their own sequence: the camera path of the same (pixel, sample)
// uses the plain seed.
constexpr uint64_t kLightPathSeed = 0x6c696768745f7472ull;  // "light_tr"
// Russian roulette on the throughput relative to the start: a light path survives with
// probability min(1, throughput / start). (The path tracer's weight window at 1/4 kept
// light paths bouncing between diffuse walls for 8.5 rays each on CBspheres; this one
// gave the same error for 20% less time.)
constexpr float kRouletteFloor = 1.0f;

}  // namespace

bool scene_has_delta_lobes(const Scene& scene) {
  return std::any_of(scene.materials.begin(), scene.materials.end(), has_delta_lobe);
}

LightTracingDecision light_tracing_decision(const Scene& scene, const LightSet& lights, const Camera& camera,
                                            const RenderSettings& s) {
  using LT = RenderSettings::LightTracer;
  if (s.light_tracer == LT::kOff) return {false, "off (--light-tracer off)"};
  if (s.adaptive || s.noise_target > 0)
    return {false, "off: -a and --noise-target decide from a pixel's or tile's own samples"};
  if (camera.is_orthographic())
    return {false, "off: the camera is orthographic (light tracing needs a perspective one)"};
  bool finite = false;
  for (size_t i = 0; i < lights.size(); ++i) finite = finite || lights.emitted_power(i) > 0;
  if (!finite) return {false, "off: no finite light to trace from (infinite lights stay the path tracer's)"};
  if (s.light_tracer == LT::kAuto && !scene_has_delta_lobes(scene))
    return {false, "off: no mirror, glass or smooth surface to carry light"};
  return {true, s.light_tracer == LT::kOn ? "on (--light-tracer on)" : "on: the scene has mirror or glass surfaces"};
}

uint64_t LightTracer::max_paths_per_pixel(uint32_t s0, uint32_t s1) {
  constexpr uint32_t kB = kSamplesPerLightPath;
  // Of samples [0, n), a pixel whose id is r modulo kB traces one in each whole block and
  // one in the part block n / kB when its pick, (r + n / kB) % kB, lies below n % kB.
  auto before = [](uint32_t r, uint32_t n) -> uint64_t { return n / kB + ((r + n / kB) % kB < n % kB ? 1 : 0); };
  if (s1 <= s0) return 0;
  uint64_t most = 0;
  for (uint32_t r = 0; r < kB; ++r) most = std::max(most, before(r, s1) - before(r, s0));
  return most;
}

LightTracer::LightTracer(const Scene& scene, const Accel& accel, const LightSet& lights, const Camera& camera,
                         const RenderSettings& s)
    : scene_(scene),
      accel_(accel),
      lights_(lights),
      camera_(camera),
      max_depth_(s.max_depth),
      width_(s.camera.width),
      height_(s.camera.height),
      splat_gain_(std::ldexp(1.0f, -s.splat_exponent.value_or(0))),
      targets_(scene) {
  double total = 0;
  std::vector<double> power(lights.size());
  for (size_t i = 0; i < lights.size(); ++i) total += power[i] = lights.emitted_power(i);
  cdf_.resize(lights.size());
  pmf_.resize(lights.size());
  traced_.assign(lights.size(), 0);
  double acc = 0;
  for (size_t i = 0; i < lights.size(); ++i) {
    acc += power[i];
    cdf_[i] = total > 0 ? float(acc / total) : 0;
    // The probability the float cdf gives (u is a float in [0, 1)), not the double's.
    pmf_[i] = cdf_[i] - (i ? cdf_[i - 1] : 0.0f);
    traced_[i] = pmf_[i] > 0;
  }
}

void LightTracer::trace(uint64_t seed, uint64_t pixel_id, uint32_t sample, SplatSink& splats, bool odd,
                        RayCounters& counters) const {
  splats.count_path(odd);
  Sampler sampler(seed ^ kLightPathSeed, pixel_id, sample);
  const float u_light = sampler.next_1d(), u_pick = sampler.next_1d(), u_dir2 = sampler.next_1d();
  const Vec2 u_pos = sampler.next_2d(), u_dir = sampler.next_2d();
  if (cdf_.empty()) return;
  const size_t li =
      std::min(size_t(std::upper_bound(cdf_.begin(), cdf_.end(), u_light) - cdf_.begin()), cdf_.size() - 1);
  if (!(pmf_[li] > 0)) return;
  LightPoint e;
  if (!lights_.emission_point(li, u_pick, u_pos, &e)) return;
  float pdf_dir = 0;
  const Vec3 dir = targets_.sample(e.q, u_dir2, u_dir, &pdf_dir);
  if (!(pdf_dir > 0)) return;
  const Light& light = lights_.light(li);
  Rgb beta = lights_.emitted_toward(li, e, dir) / (pmf_[li] * e.area_pdf * pdf_dir);
  if (beta.is_black() || !beta.is_finite()) return;
  const float start = beta.max();
  Ray ray;
  ray.o = e.n == Vec3{} ? e.q : offset_point(e.q, e.err, e.n, dir);
  ray.d = dir;
  ray.tmin = 0;
  ray.tmax = std::numeric_limits<float>::infinity();
  thread_local std::optional<Material> textured;  // made once a thread (as in Integrator::walk)
  textured.reset();
  int smooth = 0;                  // vertices before this one that scattered by a non-delta lobe
  for (int depth = 1;; ++depth) {  // the path's vertex y_depth, counted from the light
    Hit hit;
    ++counters.rays;
    if (!accel_.intersect(ray, &hit)) return;
    if (depth == 1 && light.is_delta()) {
      // A point or spot light's falloff is 1 / (c + l d + q d^2) (CS184's, physical with
      // q = 1 alone), where the flux it carries falls as 1 / d^2.
      const float d = hit.t;
      beta *= d * d / (light.att_constant + light.att_linear * d + light.att_quadratic * d * d);
    }
    SurfacePoint sp = make_surface_point(scene_, ray, hit);
    std::optional<Vec3> coat_ns;
    const Material& m = material_at(scene_, hit, &sp, &textured, &coat_ns);
    if (m.kind == Material::Kind::kPbr && !m.absorption.is_black() && dot(sp.ng, ray.d) > 0) {  // as the path tracer
      const float t = hit.t;
      beta *= Rgb(fm::exp(-m.absorption.r * t), fm::exp(-m.absorption.g * t), fm::exp(-m.absorption.b * t));
    }
    if (m.kind == Material::Kind::kEmission) return;  // emitters do not reflect
    const Vec3 w_prev = -ray.d;
    Vec3 ng = sp.ng, ns = sp.ns;
    const bool dielectric = m.is_dielectric();
    if (!dielectric && dot(ng, w_prev) < 0) {
      ng = -ng;
      ns = -ns;
    }
    const Frame frame(ns);
    const Vec3 wo = frame.to_local(w_prev);
    if (coat_ns) textured->coat_normal = frame.to_local(dot(sp.ns, ns) < 0 ? -*coat_ns : *coat_ns);
    // A connection here makes a path with smooth + 1 smooth vertices (this one too).
    if (depth >= 2 && !m.is_delta() && smooth + 1 <= kMaxSmoothVertices)
      connect(sp, m, frame, wo, w_prev, ng, dielectric, beta, sampler, splats, odd, counters);
    if (depth >= max_depth_) return;

    const float u1 = sampler.next_1d();
    const Vec2 u2 = sampler.next_2d();
    BsdfSample bs;
    if (!bsdf_sample(m, wo, u1, u2, &bs)) return;
    if (depth == 1 && !bs.delta) return;  // camera -> ... -> smooth -> light: the path tracer's
    // A delta hit off the targets (a texture made it smooth): only the cones' directions
    // reach it, so its paths are the path tracer's (Integrator::leave_to_light_tracer).
    if (depth == 1 && !targets_.aims_at(sp.material)) return;
    smooth += !bs.delta;
    if (smooth + 1 > kMaxSmoothVertices) return;  // no later connection is the light tracer's
    const Vec3 wi = frame.to_world(bs.wi);
    if (!dielectric && dot(wi, ng) <= 0) return;
    // The adjoint BSDF's weight: a delta lobe's without the radiance's 1/eta^2; a smooth
    // lobe's from f(wi, wo) (the camera side first, as the path tracer evaluates it).
    // (A clearcoat's Fresnel is taken at the viewing direction: a delta lobe under it is
    // weighed by it at wi, the camera side, not at wo: delta_adjoint_factor.)
    Rgb w = bs.delta ? bs.weight * (bs.etap * bs.etap) : bsdf_eval(m, bs.wi, wo) * (std::fabs(bs.wi.z) / bs.pdf);
    if (bs.delta && m.clearcoat > 0) w *= delta_adjoint_factor(m, wo, bs.wi);
    const float denom = std::fabs(dot(w_prev, ng)) * std::fabs(bs.wi.z);
    if (!(denom > 0)) return;
    w *= std::fabs(wo.z) * std::fabs(dot(wi, ng)) / denom;  // shading normals' correction
    beta *= w;
    if (beta.is_black() || !beta.is_finite()) return;
    if (depth >= 2) {
      const float rr = beta.max() / (start * kRouletteFloor);
      if (rr < 1) {
        const float q = std::max(0.0f, 1 - rr);
        if (sampler.next_1d() < q) return;
        beta = beta / (1 - q);
      }
    }
    ray.o = offset_ray_origin(sp, wi);
    ray.d = wi;
    ray.tmin = 0;
    ray.tmax = std::numeric_limits<float>::infinity();
  }
}

void LightTracer::connect(const SurfacePoint& sp, const Material& m, const Frame& frame, Vec3 wo, Vec3 w_prev, Vec3 ng,
                          bool dielectric, Rgb beta, Sampler& sampler, SplatSink& splats, bool odd,
                          RayCounters& counters) const {
  const Vec2 u_lens = camera_.is_thin_lens() ? sampler.next_2d() : Vec2{};
  CameraConnection cc;
  if (!camera_.connect(sp.p, u_lens, &cc)) return;
  if (!dielectric && dot(cc.wi, ng) <= 0) return;  // the camera behind a reflecting surface
  const Rgb f = bsdf_eval(m, frame.to_local(cc.wi), wo);
  if (f.is_black()) return;
  const float cos_prev = std::fabs(dot(w_prev, ng));
  if (!(cos_prev > 0)) return;
  const Rgb value = beta * f * (std::fabs(wo.z) * std::fabs(dot(cc.wi, ng)) / cos_prev * cc.weight);
  if (value.is_black()) return;
  Ray shadow;
  shadow.o = offset_ray_origin(sp, cc.wi);
  shadow.d = cc.wi;
  shadow.tmin = 0;
  // Short of the near clip, as the camera's own rays start past it: what lies nearer the
  // lens (a wall the camera sits in) is not seen, and does not block the connection.
  shadow.tmax = (length(cc.lens - shadow.o) - cc.near) * (1 - 1e-5f);
  ++counters.shadow_rays;
  if (accel_.occluded(shadow)) return;
  // The camera counts film rows from the bottom; the image's row 0 is the top.
  const int px = std::min(int(cc.fx), width_ - 1), py = height_ - 1 - std::min(int(cc.fy), height_ - 1);
  if (splats.add(px, py, value * splat_gain_, odd)) ++counters.splats;
}

}  // namespace tessera
