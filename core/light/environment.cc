#include "core/light/environment.h"

#include <algorithm>
#include <cmath>

#include "core/math/float_math.h"

namespace tessera {
namespace {

// Index i with cdf[i] <= u < cdf[i + 1], skipping zero-probability entries.
size_t find_interval(const std::vector<float>& cdf, size_t offset, size_t n, float u) {
  const auto first = cdf.begin() + ptrdiff_t(offset), last = first + ptrdiff_t(n + 1);
  size_t i = size_t(std::upper_bound(first, last, u) - first);
  i = std::clamp<size_t>(i, 1, n) - 1;
  while (i + 1 < n && !(cdf[offset + i + 1] > cdf[offset + i])) ++i;  // a flat step: the next that has mass
  return i;
}

}  // namespace

EnvironmentMap::EnvironmentMap(RgbImage image, float rotation_deg) : image_(std::move(image)) {
  const double r = double(rotation_deg) * M_PI / 180;
  cos_r_ = float(std::cos(r));
  sin_r_ = float(std::sin(r));
  const int w = image_.width, h = image_.height;
  col_cdf_.assign(size_t(h) * (w + 1), 0);
  cell_p_.assign(size_t(w) * h, 0);
  row_cdf_.assign(size_t(h) + 1, 0);
  row_p_.assign(size_t(h), 0);
  std::vector<double> row_sum(size_t(h), 0);
  double total = 0;
  // A pixel's weight is the mean of the radiance over its cell as radiance() sees it,
  // bilinearly filtered: 1/8, 3/4, 1/8 of its neighbours and itself in each direction
  // (wrapping in x, clamped in y). Weighting by the pixel alone leaves a dim pixel next to
  // a bright one (the sun's rim) with a tiny probability but half the bright radiance:
  // rare samples of huge weight, fireflies on every rough surface.
  std::vector<double> lum(size_t(w) * h);
  for (size_t i = 0; i < lum.size(); ++i) lum[i] = image_.texels[i].luminance();
  constexpr double kTap[3] = {0.125, 0.75, 0.125};
  auto filtered = [&](int x, int y) {
    double sum = 0;
    for (int j = -1; j <= 1; ++j)
      for (int i = -1; i <= 1; ++i) {
        const int xx = ((x + i) % w + w) % w, yy = std::clamp(y + j, 0, h - 1);
        sum += kTap[i + 1] * kTap[j + 1] * lum[size_t(yy) * w + size_t(xx)];
      }
    return sum;
  };
  for (int y = 0; y < h; ++y) {
    const double sin_t = std::sin(M_PI * (y + 0.5) / h);
    double acc = 0;
    std::vector<double> c(size_t(w) + 1, 0);
    for (int x = 0; x < w; ++x) {
      acc += filtered(x, y) * sin_t;
      c[size_t(x) + 1] = acc;
    }
    for (int x = 0; x <= w; ++x)
      col_cdf_[size_t(y) * (w + 1) + x] = acc > 0 ? float(c[size_t(x)] / acc) : float(x) / float(w);
    col_cdf_[size_t(y) * (w + 1) + w] = 1;
    row_sum[size_t(y)] = acc;
    total += acc;
  }
  double acc = 0;
  for (int y = 0; y < h; ++y) {
    acc += row_sum[size_t(y)];
    row_cdf_[size_t(y) + 1] = total > 0 ? float(acc / total) : 0;
    row_p_[size_t(y)] = total > 0 ? float(row_sum[size_t(y)] / total) : 0;
  }
  if (total > 0) row_cdf_[size_t(h)] = 1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t o = size_t(y) * (w + 1);
      cell_p_[size_t(y) * w + x] = row_p_[size_t(y)] * (col_cdf_[o + x + 1] - col_cdf_[o + x]);
    }
}

Vec2 EnvironmentMap::to_uv(Vec3 w) const {
  // Undo the rotation about +Y, then CS184's angles.
  const Vec3 l{cos_r_ * w.x - sin_r_ * w.z, w.y, sin_r_ * w.x + cos_r_ * w.z};
  const float theta = std::acos(std::clamp(l.y, -1.0f, 1.0f));
  float phi = std::atan2(-l.z, l.x) + kPi;
  float u = phi / (2 * kPi);
  if (!(u < 1)) u = 0;  // phi = 2 pi wraps
  if (!(u >= 0)) u = 0;
  return {u, std::clamp(theta / kPi, 0.0f, 1.0f)};
}

Rgb EnvironmentMap::radiance(Vec3 w) const {
  const Vec2 uv = to_uv(w);
  const int W = image_.width, H = image_.height;
  const float x = uv.x * W - 0.5f, y = uv.y * H - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y), tx = x - fx, ty = y - fy;
  const int x0 = int(fx), y0 = int(fy);
  auto at = [&](int i, int j) {
    i = ((i % W) + W) % W;  // wrap in x
    j = std::clamp(j, 0, H - 1);
    return image_.texels[size_t(j) * W + size_t(i)];
  };
  return at(x0, y0) * ((1 - tx) * (1 - ty)) + at(x0 + 1, y0) * (tx * (1 - ty)) + at(x0, y0 + 1) * ((1 - tx) * ty) +
         at(x0 + 1, y0 + 1) * (tx * ty);
}

bool EnvironmentMap::sample(Vec2 u, Vec3* w, float* pdf) const {
  const int W = image_.width, H = image_.height;
  if (!(row_cdf_[size_t(H)] > 0)) return false;
  const size_t y = find_interval(row_cdf_, 0, size_t(H), u.x);
  const float rp = row_cdf_[y + 1] - row_cdf_[y];
  if (!(rp > 0)) return false;
  const float du = std::clamp((u.x - row_cdf_[y]) / rp, 0.0f, 1.0f);  // reused within the row
  const size_t o = y * size_t(W + 1);
  const size_t x = find_interval(col_cdf_, o, size_t(W), u.y);
  const float cp = col_cdf_[o + x + 1] - col_cdf_[o + x];
  if (!(cp > 0)) return false;
  const float dv = std::clamp((u.y - col_cdf_[o + x]) / cp, 0.0f, 1.0f);
  const float uu = (float(x) + dv) / float(W), vv = (float(y) + du) / float(H);
  const float theta = vv * kPi, phi = uu * 2 * kPi - kPi;
  const float st = fm::sin(theta);
  if (!(st > 0)) return false;
  // Inverse of to_uv: l = (sin t cos phi', cos t, -sin t sin phi') with phi' = phi, then rotate.
  const Vec3 l{st * fm::cos(phi), fm::cos(theta), -st * fm::sin(phi)};
  *w = Vec3{cos_r_ * l.x + sin_r_ * l.z, l.y, -sin_r_ * l.x + cos_r_ * l.z};
  *pdf = cell_p_[y * size_t(W) + x] * float(W) * float(H) / (2 * kPi * kPi * st);
  return *pdf > 0 && std::isfinite(*pdf);
}

float EnvironmentMap::pdf(Vec3 w) const {
  const Vec2 uv = to_uv(w);
  const int W = image_.width, H = image_.height;
  // sin theta from the direction itself: sin(acos(y)) loses precision near the poles.
  const float st = std::sqrt(w.x * w.x + w.z * w.z);
  if (!(st > 0)) return 0;
  const int x = std::min(int(uv.x * W), W - 1), y = std::min(int(uv.y * H), H - 1);
  return cell_p_[size_t(y) * W + size_t(x)] * float(W) * float(H) / (2 * kPi * kPi * st);
}

}  // namespace tessera
