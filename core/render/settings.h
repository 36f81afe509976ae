// Everything that determines a rendered image besides the scene. Two renders with equal
// settings and scene produce bit-identical films, whatever the threads or tiling.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/camera/camera.h"

namespace tessera {

// A rectangle of pixels, in image coordinates (row 0 is the top row).
struct Rect {
  int x = 0, y = 0, w = 0, h = 0;
  int64_t area() const { return int64_t(w) * h; }
};

struct RenderSettings {
  int spp = 64;           // -s: camera samples per pixel (a maximum with -a)
  int light_samples = 1;  // -l: samples per non-delta light per shading point
  int max_depth = 16;     // -m: scattering events per path (0 = emitters only)
  bool adaptive = false;  // -a given
  int adaptive_batch = 32;
  float adaptive_tolerance = 0.05f;
  uint64_t seed = 0;
  int pass_spp = 16;  // samples per progressive pass (the merge unit of the farm)
  // Estimator switches, for measuring what each technique costs and buys (bench/). Both
  // variants stay unbiased: without NEE emitters are found by BSDF sampling alone; without
  // MIS area lights are found by light sampling alone.
  bool nee = true;
  bool mis = true;
  CameraSettings camera;
  Rect window;  // the part of the image rendered (-p); whole image when empty

  Rect effective_window() const { return window.area() > 0 ? window : Rect{0, 0, camera.width, camera.height}; }
  // The sample-index ranges of the passes. Films are merged pass by pass in this order.
  // With -a B, passes end where CS184 checks convergence: after B+1, 2B+1, ... samples.
  std::vector<std::pair<uint32_t, uint32_t>> passes() const;
};

}  // namespace tessera
