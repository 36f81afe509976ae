#include "core/render/settings.h"

#include <algorithm>
#include <cmath>

#include "core/math/hash.h"
#include "core/render/aov.h"

namespace tessera {

namespace {

void require(bool ok, const char* flag, const std::string& reason) {
  if (!ok) throw SettingsError(flag, reason);
}

std::string range(int64_t lo, int64_t hi) { return "must be in " + std::to_string(lo) + ".." + std::to_string(hi); }

}  // namespace

uint64_t RenderSettings::sample_seed() const {
  if (!frame) return seed;
  // splitmix64 of the seed and the frame: neighbouring frames get unrelated sequences.
  return mix64(seed ^ (0x9E3779B97F4A7C15ull * (uint64_t(uint32_t(*frame)) + 1)));
}

void RenderSettings::validate() const {
  require(spp >= 1 && spp <= kMaxSpp, "-s", range(1, kMaxSpp));
  require(light_samples >= 1 && light_samples <= kMaxLightSamples, "-l", range(1, kMaxLightSamples));
  require(max_depth >= 0 && max_depth <= kMaxDepth, "-m", range(0, kMaxDepth));
  require((aovs & ~kAovKnown) == 0, "--aov", "unknown AOV bits " + std::to_string(aovs & ~kAovKnown));
  require(!denoise || (aovs & kAovDenoising) == kAovDenoising, "--denoise",
          "needs the denoising layers (--aov denoising: albedo, normal, depth and halves)");
  if (adaptive)
    require(adaptive_batch >= 1 && adaptive_batch <= kMaxSpp && std::isfinite(adaptive_tolerance) &&
                adaptive_tolerance >= 0,
            "-a", "batch " + range(1, kMaxSpp) + " and tolerance must be >= 0");
  require(light_tracer != LightTracer::kOn || (!adaptive && noise_target <= 0), "--light-tracer",
          "on needs every pixel's samples (light paths land anywhere on the frame): not with -a or --noise-target");
  require(pass_spp >= 1 && pass_spp <= kMaxSpp, "--pass-spp", range(1, kMaxSpp));
  require(!splat_exponent || (*splat_exponent >= 0 && *splat_exponent <= 100), "--light-tracer",
          "splat exponent " + std::to_string(splat_exponent.value_or(0)) + " is not in 0..100");
  require(tile_size >= 1 && tile_size <= kMaxTileSize, "--tile", range(1, kMaxTileSize));
  require(!frame || (*frame >= -kMaxFrame && *frame <= kMaxFrame), "--frame", range(-kMaxFrame, kMaxFrame));
  if (environment)
    for (const float c : {environment->r, environment->g, environment->b})
      require(std::isfinite(c) && c >= 0 && c <= 1e20f, "--env-color", "each channel must be in 0..1e20");
  require(environment_map.size() <= kMaxEnvironmentPath, "--env", "a path of at most 4096 bytes");
  require(std::isfinite(environment_strength) && environment_strength >= 0 && environment_strength <= 1e20f,
          "--env-strength", "must be in 0..1e20");
  if (environment)  // the radiance is their product: bounded as emission is (1e20^2 overflowed float)
    for (const float c : {environment->r, environment->g, environment->b})
      require(double(c) * environment_strength <= 1e20, "--env-strength",
              "times --env-color is radiance, at most 1e20 (" + std::to_string(double(c) * environment_strength) + ")");
  require(std::isfinite(environment_rotation) && std::fabs(environment_rotation) <= 1e6f, "--env-rotate",
          "must be a finite angle in degrees (at most 1e6)");
  require(std::isfinite(exposure) && std::fabs(exposure) <= kMaxExposure, "--exposure",
          "must be a finite EV in -64..64");
  require(animation.size() <= kMaxAnimationName, "--animation", "a name of at most 256 bytes");
  require(std::isfinite(fps) && fps >= kMinFps && fps <= kMaxFps, "--fps", "must be between 1e-6 and 1e6");
  require(std::isfinite(noise_target) && noise_target >= 0 && noise_target <= kMaxNoiseTarget, "--noise-target",
          "must be in 0..1e9");
  require(camera.width >= 1 && camera.width <= kMaxImageSide && camera.height >= 1 && camera.height <= kMaxImageSide,
          "-r", "width and height " + range(1, kMaxImageSide));
  // (As a camera path's keys: a lens of 2e18 put rays where Embree aborts the process, a
  // focal distance of 1e20 made every ray's direction zero.)
  require(std::isfinite(camera.lens_radius) && camera.lens_radius >= 0 && camera.lens_radius <= kMaxLensRadius, "-b",
          "lens radius must be in 0..1e12");
  require(
      std::isfinite(camera.focal_distance) && camera.focal_distance > 0 && camera.focal_distance <= kMaxFocalDistance,
      "-d", "focal distance must be > 0 and at most 1e12");
  if (window.area() > 0)
    require(window.x >= 0 && window.y >= 0 && window.w >= 1 && window.h >= 1 &&
                int64_t(window.x) + window.w <= camera.width && int64_t(window.y) + window.h <= camera.height,
            "-p", "the cell must lie inside the -r image");
  const Rect w = effective_window();
  require(w.area() <= kMaxPixels, window.area() > 0 ? "-p" : "-r",
          std::to_string(w.area()) + " pixels; at most " + std::to_string(kMaxPixels) + " in one frame");
  const int64_t tiles = tile_count();
  require(tiles <= kMaxTiles, "--tile",
          std::to_string(tiles) + " tiles; at most " + std::to_string(kMaxTiles) + ": use a larger --tile");
}

int64_t RenderSettings::tile_count() const {
  const Rect w = effective_window();
  return ((int64_t(w.w) + tile_size - 1) / tile_size) * ((int64_t(w.h) + tile_size - 1) / tile_size);
}

RenderSettings RenderSettings::at_frame() const {
  RenderSettings s = *this;
  if (!camera.path) return s;
  const CameraPath::At a = camera.path->at(frame.value_or(0));
  s.camera.pose = a;
  if (a.lens_radius) s.camera.lens_radius = *a.lens_radius;
  if (a.focal_distance) s.camera.focal_distance = *a.focal_distance;
  if (a.max_depth) s.max_depth = *a.max_depth;
  return s;
}

void RenderSettings::keep_frames_camera_only() {
  if (camera.path) camera.path = std::make_shared<const CameraPath>(camera.path->for_frame(frame.value_or(0)));
}

std::vector<std::pair<uint32_t, uint32_t>> RenderSettings::passes() const {
  std::vector<std::pair<uint32_t, uint32_t>> out;
  const uint32_t total = uint32_t(std::max(spp, 0));
  uint32_t start = 0;
  const uint32_t step = uint32_t(std::max(1, adaptive ? adaptive_batch : pass_spp));
  while (start < total) {
    uint32_t end = start + step + ((adaptive && start == 0) ? 1 : 0);
    end = std::min(end, total);
    out.emplace_back(start, end);
    start = end;
  }
  return out;
}

}  // namespace tessera
