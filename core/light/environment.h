// An image environment: a lat-long radiance map around the scene, importance sampled by
// luminance with MIS like every light (pbrt's ImageInfiniteLight, CS184's -e).
//
// Directions follow CS184 (format doc 7.6): theta = acos(w.y) from +Y (row 0 at the top),
// phi = atan2(-w.z, w.x) + pi across the columns; radiance is looked up bilinearly (wrap
// in x, clamp in y). The map turns by `rotation_deg` about +Y. Sampling is piecewise
// constant per pixel, proportional to the luminance of the filtered map over the pixel's
// cell x sin(theta) (a marginal over rows, a conditional over columns), so pdf(w) =
// p_pixel W H / (2 pi^2 sin theta).
#pragma once

#include <memory>
#include <vector>

#include "core/math/vec.h"
#include "core/scene/image_read.h"

namespace tessera {

class EnvironmentMap {
 public:
  EnvironmentMap(RgbImage image, float rotation_deg);

  // Radiance arriving from direction w (unit, world space); `scale` not applied.
  Rgb radiance(Vec3 w) const;
  // Draws a direction; false when the map is black (it emits nothing).
  bool sample(Vec2 u, Vec3* w, float* pdf) const;
  float pdf(Vec3 w) const;
  int width() const { return image_.width; }
  int height() const { return image_.height; }

 private:
  Vec2 to_uv(Vec3 w) const;  // in [0, 1)^2

  RgbImage image_;
  float cos_r_ = 1, sin_r_ = 0;
  std::vector<float> row_cdf_;  // height + 1 entries, 0 .. 1
  std::vector<float> col_cdf_;  // per row: width + 1 entries, 0 .. 1
  std::vector<float> row_p_;    // probability of each row
  std::vector<float> cell_p_;   // probability of each pixel (row_p x conditional)
};

}  // namespace tessera
