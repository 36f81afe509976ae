// Light tracing for the caustic paths (BDPT's t = 1 strategy, Veach 1997 ch. 10; pbrt-v4's
// LightPathIntegrator), beside the path tracer, as a partition of path space:
//
//   the light tracer's   camera -> smooth -> ... -> delta -> light  (the camera's first hit
//                         scattered by a non-delta lobe, the light's by a delta one): the
//                         path camera -> diffuse -> mirror/glass -> light and its longer kin
//   the path tracer's    every other path (Integrator::leave_to_light_tracer ends the
//                         others' count at that light)
//
// so nothing is counted twice and the sum stays unbiased. A unidirectional path tracer can
// only find those paths by its BSDF samples hitting the light through the mirror or glass
// (and never a point light's): they are 93-96% of its variance on the CS184 spheres boxes
// (issue 28); from the light they are found by a connection to the camera.
//
// One light path per kSamplesPerLightPath camera samples, numbered by (pixel, sample) like
// the camera's, so the image does not depend on threads or tiles. Each starts on a finite light picked by power
// (LightSet::emission_point), aimed at the bounding sphere of a mirror or glass shape
// (delta_targets.h), continues only if its first hit scatters by a delta lobe,
// and at every later vertex with a smooth lobe is connected to the camera (Camera::connect):
// a splat on the pixel it lands in (splats.h). Transport is adjoint: refraction carries no
// 1/eta^2 (flux, not radiance), and shading normals get Veach's correction
// |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|).
//
// Falls back to the path tracer alone (light_tracing_decision says why): orthographic
// cameras, -a and --noise-target (they decide from a pixel's or tile's own sums), scenes
// lit only by infinite lights (the environment, directional and ambient lights stay the
// path tracer's, caustics included), and, for auto, scenes without a delta lobe.
#pragma once

#include <string>
#include <vector>

#include "core/accel/accel.h"
#include "core/camera/camera.h"
#include "core/light/lights.h"
#include "core/render/delta_targets.h"
#include "core/render/integrator.h"
#include "core/render/settings.h"
#include "core/render/splats.h"
#include "core/sampling/sampler.h"
#include "core/scene/scene.h"

namespace tessera {

// Whether a render with these settings traces light paths, and a line saying why.
struct LightTracingDecision {
  bool on = false;
  std::string why;
};
LightTracingDecision light_tracing_decision(const Scene& scene, const LightSet& lights, const Camera& camera,
                                            const RenderSettings& settings);

// Whether any surface of the scene can scatter by a delta lobe (has_delta_lobe).
bool scene_has_delta_lobes(const Scene& scene);

class LightTracer {
 public:
  // One light path for every this many camera samples: of the samples 4k to 4k + 3 of
  // image pixel p, the one at (p + k) % 4 traces one (traces()). So a pixel traces one in
  // each aligned block, on an even and an odd sample in turn: each half-buffer gets light
  // paths from every pixel, even in a window one pixel wide. (Until protocol 11 it was the
  // samples with (p + s) % 4 == 0, which gave all of a pixel's to the half of its parity.)
  // On CBspheres (480x360, 64 spp) the light tracer's error is a small part of the image's
  // once every sample has one: a light path per 4 samples kept 93% of the error reduction
  // for 25% of the cost (docs/light-tracing.md).
  static constexpr uint32_t kSamplesPerLightPath = 4;
  // Paths with any number of smooth vertices are the light tracer's (a limit of 1 or 2
  // left the walls' indirect caustics to the path tracer: 2-4x worse there).
  static constexpr int kMaxSmoothVertices = 1 << 16;
  // The path tracer's continuations from the first smooth vertex of a path seen through
  // mirrors or glass (Integrator::set_specular_splits): the pixels light paths cannot
  // reach. On CBspheres (64 spp, 2 seeds) 1, 2, 3, 4, 8 gave the spheres' pixels 1.0, 1.9,
  // 2.6, 3.5, 6.6 times less error for 8%, 20%, 31%, 56% more time, the image's
  // efficiency 1.32x at 2 and flat from 3 to 8; CBdragon's image was best at 2 (the
  // dragon's own error is mostly its facets' aliasing, which splitting does not touch),
  // cornell-spheres.gltf's 1.23x at 2 and 1.31x at 3 (docs/light-tracing.md).
  static constexpr int kSpecularSplits = 2;
  static bool traces(uint64_t pixel_id, uint32_t sample) {
    return sample % kSamplesPerLightPath == (pixel_id + sample / kSamplesPerLightPath) % kSamplesPerLightPath;
  }
  // How many of samples [s0, s1) trace a light path for a pixel, at most over all pixels:
  // one per whole block of four, plus one for each part block at either end.
  static uint64_t max_paths_per_pixel(uint32_t s0, uint32_t s1);

  LightTracer(const Scene& scene, const Accel& accel, const LightSet& lights, const Camera& camera,
              const RenderSettings& settings);
  // Per LightSet index: whether light paths start there (for Integrator::leave_to_light_tracer).
  const std::vector<uint8_t>& traced_lights() const { return traced_; }
  // Per material: whether light paths aim at its shapes (DeltaTargets::target_materials).
  const std::vector<uint8_t>& target_materials() const { return targets_.target_materials(); }
  // The light path of camera sample `sample` of image pixel `pixel_id`: its splats into
  // `splats` (with `odd`, its odd plane too). Thread-safe.
  void trace(uint64_t seed, uint64_t pixel_id, uint32_t sample, SplatSink& splats, bool odd,
             RayCounters& counters) const;

 private:
  void connect(const SurfacePoint& sp, const Material& m, const Frame& frame, Vec3 wo, Vec3 w_prev, Vec3 ng,
               bool dielectric, Rgb beta, Sampler& sampler, SplatSink& splats, bool odd, RayCounters& counters) const;

  const Scene& scene_;
  const Accel& accel_;
  const LightSet& lights_;
  Camera camera_;  // (a copy: the renderer that owns this may be moved)
  int max_depth_;
  int width_, height_;
  float splat_gain_;              // 2^-splat_exponent: splats enter their sums scaled by it
  std::vector<float> cdf_, pmf_;  // lights picked by emitted power
  std::vector<uint8_t> traced_;
  DeltaTargets targets_;  // where light paths go first
};

}  // namespace tessera
