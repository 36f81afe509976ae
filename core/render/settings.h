// Everything besides the scene that fixes the image: the one owner of render settings.
// The CLI binds its flags to these fields, the wire protocol carries every one of them, and
// `validate()` is the one range check for both. Two renders with equal settings and scene
// produce bit-identical films, whatever the threads, workers or machines.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "core/camera/camera.h"
#include "core/math/rect.h"
#include "core/render/aov.h"

namespace tessera {

// A setting out of range: names the setting by its command-line flag.
class SettingsError : public std::invalid_argument {
 public:
  SettingsError(std::string flag, const std::string& reason)
      : std::invalid_argument(flag + ": " + reason), flag_(std::move(flag)) {}
  const std::string& flag() const { return flag_; }

 private:
  std::string flag_;
};

struct RenderSettings {
  // Limits, named once: far beyond any sensible render, small enough that sample counts
  // fit 32 bits per pixel and image sizes fit the wire's 16-bit-safe coordinates.
  static constexpr int kMaxSpp = 1 << 24;
  static constexpr int kMaxLightSamples = 1 << 16;
  static constexpr int kMaxDepth = 1 << 16;
  static constexpr int kMaxImageSide = 65536;
  static constexpr int kMaxTileSize = 4096;
  static constexpr double kMaxNoiseTarget = 1e9;
  // What one frame may ask for, checked before anything is allocated: the film holds 40
  // bytes a pixel (5.4 GB at the limit, past 11000 x 11000), the plan ~80 bytes a tile.
  static constexpr int64_t kMaxPixels = int64_t(1) << 27;
  static constexpr int64_t kMaxTiles = int64_t(1) << 18;

  int spp = 64;           // -s: camera samples per pixel (a maximum with -a or --noise-target)
  int light_samples = 1;  // -l: samples per area (or ambient) light per shading point
  int max_depth = 16;     // -m: scattering events per path, delta bounces included; 0 = emitters only
  // -a BATCH TOLERANCE: CS184 adaptive sampling. After BATCH+1, 2*BATCH+1, ... samples a
  // pixel stops once the 95% interval of its luminance is within TOLERANCE x mean.
  bool adaptive = false;
  int adaptive_batch = 32;
  float adaptive_tolerance = 0.05f;
  uint64_t seed = 0;  // --seed: every random number is a function of it
  // --frame N: the frame of a sequence this is. Its random numbers depend on it too, so
  // that the frames of a sequence are independent and each is the same image whether
  // rendered alone or with the others. A still (none) keeps the seed as it is.
  // Splats enter their fixed-point sums scaled by 2^-this (core/render/splats.h,
  // splat_exponent_for): unset, tessera render computes it from the scene; a farm job's is
  // set at submit, from the coordinator's copy of the scene, and travels with its tasks.
  std::optional<int> splat_exponent;
  static constexpr int kMaxFrame = 1000000;
  // -b and -d, as a camera path's keys bound them (the scene's coordinates' range).
  static constexpr float kMaxLensRadius = float(Scene::kMaxCoordinate), kMaxFocalDistance = kMaxLensRadius;
  std::optional<int> frame;
  // The seed the sampler uses: `seed`, mixed with the frame number when there is one.
  uint64_t sample_seed() const;
  // --fps: frames per second: a frame's time (for animation) is frame / fps seconds.
  static constexpr double kMaxFps = 1e6, kMinFps = 1e-6;  // (a frame time below 2^31 / 1e-6 s stays finite)
  double fps = 24;
  double time() const { return frame ? double(*frame) / fps : 0.0; }
  // --animation: which of a glTF file's animations frames follow, by name or index (empty:
  // the first). A still (no frame) shows the file's rest pose.
  static constexpr size_t kMaxAnimationName = 256;
  std::string animation;
  // --env-color R G B: a uniform environment of this radiance around the scene (light
  // from every direction, sampled with MIS like every light); none by default.
  std::optional<Rgb> environment;
  // --no-default-env turns off the neutral environment (uniform radiance 1) that a glTF
  // scene with no light at all is rendered under (Scene::unlit).
  bool default_environment = true;
  static constexpr float kDefaultEnvironment = 1.0f;
  // --env FILE (CS184's -e): a lat-long .exr or .hdr radiance map around the scene
  // (core/light/environment.h), times --env-color when given. A relative path is relative
  // to the scene file's folder: the CLI makes a user's path absolute, and a farm job names
  // the file it shipped inside the scene bundle.
  static constexpr size_t kMaxEnvironmentPath = 4096;
  std::string environment_map;
  // --env-strength scales whichever environment there is (image, colour or the default);
  // --env-rotate turns an image environment by degrees about +Y.
  float environment_strength = 1;
  float environment_rotation = 0;
  // --exposure EV: PNGs and previews show the linear values x 2^EV (for scenes in physical
  // units: a 3 lux sun renders at 1e-6); EXRs keep the scene-linear values and carry the
  // EV as their `exposure` attribute, from which every PNG made of them takes it. It
  // changes no sample: the same render at any exposure has the same EXR pixels.
  static constexpr float kMaxExposure = 64;
  float exposure = 0;
  int pass_spp = 16;  // --pass-spp: samples per progressive pass (the unit merged in order)
  // --tile: side of the square tiles the frame is cut into. It never changes the image,
  // except with a noise target, which is judged per tile.
  int tile_size = 32;
  // --noise-target: > 0 stops refining a tile once its estimated relative error (the
  // relMSE the accuracy benchmarks use, from the film's own variance) is below it, after
  // at least two passes. Reproducible: decided from merged sums at pass boundaries.
  double noise_target = 0;
  // --no-nee / --no-mis: for measuring what each technique costs and buys (bench/). Both
  // variants stay unbiased: without NEE emitters are found by BSDF sampling alone; without
  // MIS area lights are found by light sampling alone.
  bool nee = true;
  bool mis = true;
  // --light-tracer: light paths for the caustic paths camera -> diffuse -> mirror/glass ->
  // light (core/render/light_tracer.h). kAuto turns it on where the scene has a mirror or
  // glass surface and a light it can trace from (TileRenderer decides; --stats-json says).
  // Not with -a or --noise-target (they decide from a pixel's or tile's own sums, and
  // light paths land anywhere). Through the farm, tasks' splats travel with their sums
  // (server/frame_splats.h).
  enum class LightTracer : uint8_t { kOff, kOn, kAuto };
  LightTracer light_tracer = LightTracer::kAuto;
  // --aov: the AOVs written beside the image (aov.h's bits; 0: none, and no work for them).
  uint32_t aovs = 0;
  // --denoise: the final image is denoised (core/denoise/), the noisy one kept beside it in
  // the EXR. Needs aovs to hold kAovDenoising (the flag adds them).
  bool denoise = false;
  CameraSettings camera;  // -r, -b, -d, --camera: documented in core/camera/camera.h
  Rect window;            // -p: the part of the image rendered; the whole image when empty

  // Throws SettingsError for the first setting out of range.
  void validate() const;
  // The settings a frame is rendered with: with a camera path (camera.path), its values at
  // this frame (0 for a still) in camera.pose, lens radius, focal distance and max depth.
  RenderSettings at_frame() const;
  // The camera path cut to what this frame (0 for a still) takes from it
  // (CameraPath::for_frame): what a farm job's tasks carry, the frame's bits the same.
  void keep_frames_camera_only();
  // With the half-buffers (kAovHalves) a tile's sums are two planes, every sample's then
  // the odd-numbered samples' (film.h); else one.
  bool halves() const { return (aovs & kAovHalves) != 0; }
  uint32_t sum_planes() const { return halves() ? 2 : 1; }
  Rect effective_window() const { return window.area() > 0 ? window : image_rect(); }
  // The whole image (-r), which a window (-p) is part of: an EXR's display window.
  Rect image_rect() const { return Rect{0, 0, camera.width, camera.height}; }
  // Tiles the frame is cut into (FramePlan cuts them).
  int64_t tile_count() const;
  // The sample-index ranges of the passes. Films are merged pass by pass in this order.
  // With -a B, passes end where CS184 checks convergence: after B+1, 2B+1, ... samples.
  std::vector<std::pair<uint32_t, uint32_t>> passes() const;
};

}  // namespace tessera
