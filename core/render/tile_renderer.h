// Renders sample ranges of pixel rectangles into fresh sums: the unit of work of both the
// local renderer and a farm worker.
#pragma once

#include <atomic>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "core/accel/accel.h"
#include "core/camera/camera.h"
#include "core/light/lights.h"
#include "core/render/film.h"
#include "core/render/integrator.h"
#include "core/render/light_tracer.h"
#include "core/render/settings.h"
#include "core/render/splats.h"
#include "core/scene/scene.h"

namespace tessera {

struct TileStats {
  uint64_t samples = 0;
  uint64_t nan_samples = 0;  // NaN, Inf or over kMaxSampleValue: dropped, counted, reported
  RayCounters rays;
  void add(const TileStats& o) {
    samples += o.samples;
    nan_samples += o.nan_samples;
    rays.rays += o.rays.rays;
    rays.shadow_rays += o.rays.shadow_rays;
    rays.self_hits += o.rays.self_hits;
    rays.splats += o.rays.splats;
    rays.split_paths += o.rays.split_paths;
  }
};

class TileRenderer {
 public:
  // Builds the acceleration structure; `scene` must outlive the renderer. A frame of an
  // animated scene (settings.frame set, scene.animation not null) is rendered from the
  // scene posed at the frame's time, with an acceleration structure of its own. Throws
  // SettingsError("--animation") when the scene has no animation of that name or index,
  // SceneError when a pose is out of range.
  TileRenderer(const Scene& scene, const RenderSettings& settings);
  // A renderer of base's scene with other settings (another frame of a sequence, say): it
  // shares base's acceleration structure and lights, so nothing is built but the camera
  // (unless the scene is animated: each pose has its own).
  TileRenderer(const TileRenderer& base, const RenderSettings& settings);

  // Samples [s0, s1) of each pixel of `rect` whose `active` flag is set (all when active
  // is null; `active` is rect-sized, row-major). Returns rect-sized sums (two planes of
  // them with half-buffers: settings().sum_planes(), film.h). If `cancel`
  // becomes true the render stops between pixels and the result must be discarded. With
  // `aovs` (settings().aovs set), the same samples' AOV sums too, rect-sized (aov.h).
  // With light tracing (light_tracing()), each camera sample's light path too, its splats
  // added to `splats` (which must then be given: std::logic_error otherwise).
  std::vector<PixelSums> render(const Rect& rect, uint32_t s0, uint32_t s1, const uint8_t* active, TileStats* stats,
                                const std::atomic<bool>* cancel = nullptr, std::vector<AovSums>* aovs = nullptr,
                                SplatSink* splats = nullptr) const;
  // A run of passes (consecutive sample ranges, in pass order), each rendered on its own
  // and added in pass order to `base` (as render() returns; null: zero), as a film adds them: from
  // a tile's sums so far, the film's bits after those passes (FramePlan::take with more
  // than one pass). One range and no base is render()'s result. `aovs`: the passes' AOV
  // sums together (no base: integer sums add in any grouping). With light tracing, `splats`
  // (which must then be given) receives one record per pass (a farm task's: the frame's
  // splat film is the coordinator's); without, it is left empty.
  std::vector<PixelSums> render_passes(const Rect& rect, const std::vector<std::pair<uint32_t, uint32_t>>& passes,
                                       const PixelSums* base, const uint8_t* active, TileStats* stats,
                                       const std::atomic<bool>* cancel = nullptr, std::vector<AovSums>* aovs = nullptr,
                                       std::vector<SplatRecord>* splats = nullptr) const;

  // Throws SettingsError when `settings` ask the scene for what it has not: an animation
  // (--animation) it does not have, an environment map (--env) that cannot be read beside
  // it, the file's camera (--camera file) when the file's is unusable. The coordinator
  // checks a job with it at submit.
  // A camera path or turntable is checked at each of `frames` (a sequence's), else at the
  // still's frame: refused naming the frame where it fails (a path through the target).
  static void check_settings(const Scene& scene, const RenderSettings& settings, const std::vector<int>& frames = {});
  // Whether a renderer of the scene with these settings traces light paths (light_tracing()),
  // decided as the renderer decides, without building anything: the coordinator resolves a
  // job's --light-tracer auto at submit with it, so a frame's results must all carry splats
  // or none.
  static bool traces_light_paths(const Scene& scene, const RenderSettings& settings);
  // The --env image, its path relative to the scene file's folder unless absolute; null
  // without one. Throws SettingsError("--env") naming the file and the problem.
  static std::shared_ptr<const EnvironmentMap> load_environment(const Scene& scene, const RenderSettings& settings);

  // The frame the next renders are of (--frames): the random numbers and, with a camera
  // path, the camera change; the scene's acceleration structure is built once for a whole
  // sequence. Not while rendering.
  void set_frame(std::optional<int> frame);

  // Whether this frame traces light paths for its caustics (light_tracer.h), and why.
  bool light_tracing() const { return light_tracer_.has_value(); }
  const LightTracingDecision& light_tracing_decision() const { return light_decision_; }
  const Camera& camera() const { return *camera_; }
  // A frame's splat film for these settings (light_tracing() only).
  std::unique_ptr<SplatFilm> make_splat_film() const;

  const Scene& scene() const { return *scene_; }  // as posed for the frame
  const RenderSettings& settings() const { return settings_; }

 private:
  // Pose (if animated), camera and integrator for settings_'s frame; a static scene's
  // acceleration structure and lights come from `share` when it has them.
  void set_up_frame(const TileRenderer* share);
  static void check_animation(const Scene& scene, const RenderSettings& settings);

  const Scene* rest_;                   // as loaded
  std::shared_ptr<const Scene> posed_;  // an animated scene at this frame's time
  const Scene* scene_ = nullptr;        // what is rendered: rest_ or posed_
  const Scene* accel_scene_ = nullptr;  // what accel_ and lights_ were built for
  // An animated scene's geometry that no animation moves, built once for every pose.
  struct StaticPart {
    std::vector<bool> moving;  // per mesh
    std::shared_ptr<const Accel> accel;
    // The rest pose's object bounds: what CS184 framing and a turntable's centre take in
    // every frame (as TileRenderer::check_settings does), not each frame's posed objects
    // (the camera drifted and zoomed with whatever moved).
    Bounds rest_bounds;
  };
  std::shared_ptr<const StaticPart> static_part_;
  RenderSettings settings_;
  std::shared_ptr<const Accel> accel_;
  std::shared_ptr<const EnvironmentMap> environment_;  // --env's image, when given
  std::shared_ptr<const LightSet> lights_;
  std::optional<Camera> camera_;
  std::optional<Integrator> integrator_;
  std::optional<LightTracer> light_tracer_;
  LightTracingDecision light_decision_;
};

}  // namespace tessera
