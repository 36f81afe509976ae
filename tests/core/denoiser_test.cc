// The denoiser (core/denoise): its limits (a constant stays constant, a noise-free image
// comes back unchanged, bit for bit), its gain on a synthetic scene with a known answer
// (Gaussian noise and fireflies), no loss where nothing explains the detail (a mirror),
// determinism across thread counts and SIMD widths, tiny images, and the refusals of bad
// buffers.
#include "core/denoise/denoiser.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>

namespace tessera {
namespace {

// A procedural scene, supersampled 4 x 4 a pixel so that its edges are anti-aliased as a
// renderer's would be: a sky (background: no albedo or normal, depth 1e10) over a floor
// with a checker albedo lit by a smooth falloff and darkened by a soft shadow, a sphere
// shaded by n . l with a highlight, and a striped box standing in front of both. Each pixel
// also keeps the region its centre sees.
struct Scene {
  int width = 0, height = 0;
  std::vector<float> truth, albedo, normal, depth;
  std::vector<int> region;
};

struct Hit {
  int region = 0;
  float albedo[3] = {0, 0, 0}, normal[3] = {0, 0, 0}, depth = 1e10f, color[3] = {0, 0, 0};
};

Hit trace(float u, float v) {  // u, v in [0, 1), v down
  Hit h;
  const float sphere_u = 0.3f, sphere_v = 0.55f, sphere_r = 0.22f;
  const float du = (u - sphere_u) / sphere_r, dv = (v - sphere_v) / sphere_r;
  auto shade = [&](float s) {
    for (int c = 0; c < 3; ++c) h.color[c] = h.albedo[c] * s;
  };
  if (u > 0.6f && u < 0.85f && v > 0.35f && v < 0.78f) {  // the box, facing the camera
    h.region = 3;
    const bool stripe = int(std::floor(v * 40)) % 2 == 0;
    const float a[3] = {0.3f, 0.8f, stripe ? 0.3f : 0.5f};
    std::copy(a, a + 3, h.albedo);
    h.normal[2] = 1;
    h.depth = 3;
    shade(0.8f);
  } else if (du * du + dv * dv < 1) {
    h.region = 2;
    const float a[3] = {0.9f, 0.4f, 0.2f};
    std::copy(a, a + 3, h.albedo);
    const float n[3] = {du, -dv, std::sqrt(1 - du * du - dv * dv)};
    std::copy(n, n + 3, h.normal);
    const float l[3] = {0.48f, 0.64f, 0.6f};
    h.depth = 5 - n[2];
    shade(0.1f + std::max(0.f, n[0] * l[0] + n[1] * l[1] + n[2] * l[2]));
    const float hv[3] = {0.27f, 0.36f, 0.89f}, nh = std::max(0.f, n[0] * hv[0] + n[1] * hv[1] + n[2] * hv[2]);
    for (int c = 0; c < 3; ++c) h.color[c] += 0.8f * std::pow(nh, 40.f);  // a highlight: not linear in anything
  } else if (v > 0.3f) {  // the floor, receding to the horizon at v = 0.3
    h.region = 1;
    const float z = 1.5f / (v - 0.29f);
    const bool dark = (int(std::floor(u * 12 * 2 / z * 4)) + int(std::floor(z * 2))) % 2 != 0;
    const float a[3] = {dark ? 0.2f : 0.8f, dark ? 0.3f : 0.8f, dark ? 0.6f : 0.8f};
    std::copy(a, a + 3, h.albedo);
    h.normal[1] = 1;
    h.depth = z;
    // Light falling off across the floor, and the sphere's soft shadow: neither is in the features.
    const float su = (u - 0.4f) / 0.2f, sv = (v - 0.82f) / 0.06f;
    const float shadow = 1 - 0.7f * std::exp(-(su * su + sv * sv) * 2);
    shade(shadow * (0.25f + 1.2f * std::exp(-((u - 0.5f) * (u - 0.5f) + (v - 0.9f) * (v - 0.9f)) * 6)));
  } else {
    const float sky[3] = {0.5f, 0.7f, 1.0f};
    for (int c = 0; c < 3; ++c) h.color[c] = sky[c] * (1 - v);
  }
  return h;
}

Scene make_scene(int w, int h) {
  Scene s;
  s.width = w;
  s.height = h;
  const size_t n = size_t(w) * size_t(h);
  s.truth.assign(3 * n, 0);
  s.albedo.assign(3 * n, 0);
  s.normal.assign(3 * n, 0);
  s.depth.assign(n, 1e10f);
  s.region.assign(n, 0);
  constexpr int kSub = 4;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t i = size_t(y) * size_t(w) + size_t(x);
      int hits = 0;
      double depth = 0;
      for (int sy = 0; sy < kSub; ++sy)
        for (int sx = 0; sx < kSub; ++sx) {
          const Hit hit = trace((x + (sx + 0.5f) / kSub) / w, (y + (sy + 0.5f) / kSub) / h);
          for (int c = 0; c < 3; ++c) {
            s.truth[3 * i + c] += hit.color[c] / (kSub * kSub);
            s.albedo[3 * i + c] += hit.albedo[c] / (kSub * kSub);
            s.normal[3 * i + c] += hit.normal[c] / (kSub * kSub);
          }
          if (hit.region != 0) ++hits, depth += hit.depth;
        }
      if (hits) s.depth[i] = float(depth / hits);
      s.region[i] = trace((x + 0.5f) / w, (y + 0.5f) / h).region;
    }
  return s;
}

// The scene's buffers with Gaussian noise added to each half independently: a half's
// standard deviation is level x (truth + 0.05), the level rising from left to right from
// 0.2 to 1.0 times `noise`, as a render whose sample count fell across the frame would.
DenoiseBuffers noisy(const Scene& s, float noise, uint32_t seed) {
  DenoiseBuffers b;
  b.width = s.width;
  b.height = s.height;
  b.albedo = s.albedo;
  b.normal = s.normal;
  b.depth = s.depth;
  b.even = b.odd = b.color = s.truth;
  std::mt19937 rng(seed);
  std::normal_distribution<float> gauss;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const size_t i = 3 * (size_t(y) * size_t(s.width) + size_t(x)) + size_t(c);
        const float sigma = noise * (0.2f + 0.8f * x / s.width) * (s.truth[i] + 0.05f);
        b.even[i] += sigma * gauss(rng);
        b.odd[i] += sigma * gauss(rng);
        b.color[i] = 0.5f * (b.even[i] + b.odd[i]);
      }
  return b;
}

// Renderer-like noise: each half the mean of `spp` samples truth x e x m, e exponential
// (mean 1) and m 25 for one sample in 50 (fireflies), else 0.5102 (so that m's mean is 1).
// Never negative, heavy-tailed, and as noisy where the image is bright as a path tracer's.
DenoiseBuffers fireflies(const Scene& s, int spp, uint32_t seed) {
  DenoiseBuffers b = noisy(s, 0, 1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uniform;
  std::exponential_distribution<float> exponential;
  for (size_t i = 0; i < s.truth.size(); ++i) {
    float half[2];
    for (float& mean : half) {
      double sum = 0;
      for (int k = 0; k < spp; ++k) sum += s.truth[i] * (uniform(rng) < 0.02f ? 25.f : 0.5102f) * exponential(rng);
      mean = float(sum / spp);
    }
    b.even[i] = half[0];
    b.odd[i] = half[1];
    b.color[i] = 0.5f * (half[0] + half[1]);
  }
  return b;
}

double rel_mse(const std::vector<float>& x, const std::vector<float>& ref, const std::vector<bool>& mask) {
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < ref.size(); ++i)
    if (mask[i / 3]) {
      const double d = double(x[i]) - ref[i];
      sum += d * d / (double(ref[i]) * ref[i] + 0.01);
      ++n;
    }
  return sum / double(n);
}

// Pixels whose 3 x 3 neighbourhood sees more than one region.
std::vector<bool> edge_pixels(const Scene& s) {
  std::vector<bool> edge(s.region.size(), false);
  for (int y = 1; y + 1 < s.height; ++y)
    for (int x = 1; x + 1 < s.width; ++x)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (s.region[size_t((y + dy) * s.width + x + dx)] != s.region[size_t(y * s.width + x)])
            edge[size_t(y * s.width + x)] = true;
  return edge;
}

std::string refusal(const DenoiseBuffers& b) {
  try {
    denoise(b);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(accepted)";
}

void expect_relative_near(const std::vector<float>& got, const std::vector<float>& want, double tolerance) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i)
    ASSERT_LE(std::abs(double(got[i]) - want[i]), tolerance * std::abs(double(want[i])) + 1e-30) << "value " << i;
}

TEST(Denoiser, AConstantImageStaysConstant) {
  Scene s = make_scene(40, 30);
  DenoiseBuffers b = noisy(s, 0, 1);
  for (size_t i = 0; i < b.color.size(); ++i) b.color[i] = b.even[i] = b.odd[i] = i % 3 == 0 ? 0.3f : 2.5f;
  expect_relative_near(denoise(b), b.color, 1e-5);
}

TEST(Denoiser, ANoiseFreeImageComesBackUnchangedBitForBit) {
  // Zero estimated variance means the pixel is exact: the edges, textures and shading here
  // would all be touched by a filter that did not know that.
  const Scene s = make_scene(96, 64);
  const DenoiseBuffers b = noisy(s, 0, 1);
  EXPECT_EQ(denoise(b), b.color);
}

TEST(Denoiser, NoiseFreePixelsFarFromNoiseAreKeptInANoisyImage) {
  const Scene s = make_scene(96, 64);
  DenoiseBuffers b = noisy(s, 0.5f, 7);
  const DenoiseBuffers clean = noisy(s, 0, 1);
  const int split = 40, reach = 8;  // beyond the variance's 7 x 7 smoothing
  for (int y = 0; y < s.height; ++y)
    for (int x = split; x < s.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const size_t i = 3 * size_t(y * s.width + x) + size_t(c);
        b.even[i] = b.odd[i] = b.color[i] = clean.color[i];
      }
  const std::vector<float> out = denoise(b);
  for (int y = 0; y < s.height; ++y)
    for (int x = split + reach; x < s.width; ++x)
      for (int c = 0; c < 3; ++c) {
        const size_t i = 3 * size_t(y * s.width + x) + size_t(c);
        ASSERT_EQ(out[i], b.color[i]) << "pixel (" << x << ", " << y << ")";
      }
}

TEST(Denoiser, CutsTheRelativeErrorOfANoisySceneAtLeastFourfoldAndKeepsItsEdges) {
  const Scene s = make_scene(160, 120);
  const DenoiseBuffers b = noisy(s, 0.6f, 12345);
  const std::vector<float> out = denoise(b);
  const std::vector<bool> all(s.region.size(), true), edges = edge_pixels(s);
  const double before = rel_mse(b.color, s.truth, all), after = rel_mse(out, s.truth, all);
  const double edges_before = rel_mse(b.color, s.truth, edges), edges_after = rel_mse(out, s.truth, edges);
  std::printf("relMSE %.5f -> %.5f (%.1fx); on edges %.5f -> %.5f (%.1fx)\n", before, after, before / after,
              edges_before, edges_after, edges_before / edges_after);
  EXPECT_LT(after * 4, before);
  EXPECT_LT(edges_after * 2, edges_before);
}

TEST(Denoiser, CutsTheErrorOfFirefliesAndNeverGoesNegativeWhereTheInputIsNot) {
  // One sample a half: the first-order fit would overshoot below zero next to fireflies;
  // there the weighted mean is used instead.
  const Scene s = make_scene(128, 96);
  const DenoiseBuffers b = fireflies(s, 1, 99);
  const std::vector<float> out = denoise(b);
  const std::vector<bool> all(s.region.size(), true);
  EXPECT_LT(rel_mse(out, s.truth, all) * 4, rel_mse(b.color, s.truth, all));
  EXPECT_GE(*std::min_element(out.begin(), out.end()), 0.f);
}

TEST(Denoiser, KeepsDetailNoFeatureExplainsNoWorseThanItCame) {
  // A mirror reflecting a busy scene: every pixel's colour is its own (hashed), while the
  // first hit's albedo, normal and depth are the same everywhere, so no feature explains any
  // of it and no neighbour resembles it. Smoothing can only blur it; the noisy colour, a
  // candidate itself, must win wherever the filters would be worse than the noise.
  const int w = 96, h = 64;
  const size_t n = size_t(w) * size_t(h);
  std::vector<float> truth(3 * n);
  for (size_t i = 0; i < truth.size(); ++i) {
    uint32_t x = uint32_t(i) * 2654435761u;
    x ^= x >> 15;
    x *= 2246822519u;
    x ^= x >> 13;
    truth[i] = 0.2f + float(x & 0xffff) / 65535.f;  // 0.2 to 1.2
  }
  for (const float noise : {0.1f, 0.3f}) {  // a half's standard deviation over the colour (+0.05)
    DenoiseBuffers b;
    b.width = w;
    b.height = h;
    b.albedo.assign(3 * n, 0.8f);
    b.normal.assign(3 * n, 0.f);
    for (size_t i = 0; i < n; ++i) b.normal[3 * i + 2] = 1;
    b.depth.assign(n, 4.f);
    b.even = b.odd = b.color = truth;
    std::mt19937 rng(5);
    std::normal_distribution<float> gauss;
    for (size_t i = 0; i < truth.size(); ++i) {
      const float sigma = noise * (truth[i] + 0.05f);
      b.even[i] += sigma * gauss(rng);
      b.odd[i] += sigma * gauss(rng);
      b.color[i] = 0.5f * (b.even[i] + b.odd[i]);
    }
    const std::vector<bool> all(n, true);
    const double before = rel_mse(b.color, truth, all), after = rel_mse(denoise(b), truth, all);
    std::printf("noise %.1f: relMSE %.5f -> %.5f\n", noise, before, after);
    // Within 2%: twice the relative standard error of a mean of 3n squared Gaussian errors,
    // sqrt(2 / 3n) = 1%, so that the claim does not hang on this one draw of the noise.
    EXPECT_LE(after, before * (1 + 2 * std::sqrt(2.0 / double(3 * n)))) << "noise " << noise;
  }
}

TEST(Denoiser, GivesTheSameBitsForAnyThreadCount) {
  const Scene s = make_scene(77, 45);  // tiles overhang the image on both sides
  const DenoiseBuffers b = noisy(s, 0.5f, 3);
  DenoiseOptions one, two, three;
  one.threads = 1;
  two.threads = 2;
  three.threads = 3;
  const std::vector<float> a = denoise(b, one);
  EXPECT_EQ(a, denoise(b, two));
  EXPECT_EQ(a, denoise(b, three));
}

TEST(Denoiser, GivesTheSameBitsWithFourAndEightLanes) {
  // The 8-lane (AVX2) kernels do lane by lane what the 4-lane ones do, without FMA.
  const Scene s = make_scene(77, 45);
  const DenoiseBuffers b = noisy(s, 0.5f, 4);
  DenoiseOptions narrow;
  narrow.wide_lanes = false;
  EXPECT_EQ(denoise(b), denoise(b, narrow));
}

TEST(Denoiser, HandlesOnePixelOneRowAndOneColumn) {
  for (const auto& [w, h] : {std::pair{1, 1}, std::pair{37, 1}, std::pair{1, 23}}) {
    const Scene s = make_scene(w, h);
    const DenoiseBuffers b = noisy(s, 0.5f, 5);
    const std::vector<float> out = denoise(b);
    ASSERT_EQ(out.size(), b.color.size());
    for (float v : out) ASSERT_TRUE(std::isfinite(v));
    if (w * h == 1) {  // alone in its window, each half's fit is the half itself
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(out[size_t(c)], 0.5f * (b.even[size_t(c)] + b.odd[size_t(c)]), 1e-6f);
    }
  }
}

TEST(Denoiser, RefusesMissingMisSizedAndNonFiniteBuffersNamingThem) {
  const DenoiseBuffers good = noisy(make_scene(3, 2), 0.5f, 9);
  DenoiseBuffers b = good;
  b.albedo.clear();
  EXPECT_EQ(refusal(b), "denoise: the 'albedo' buffer has 0 values, 3 x 3 x 2 = 18 expected");
  b = good;
  b.depth.push_back(1);
  EXPECT_EQ(refusal(b), "denoise: the 'depth' buffer has 7 values, 1 x 3 x 2 = 6 expected");
  b = good;
  b.normal.resize(17);
  EXPECT_NE(refusal(b).find("'normal'"), std::string::npos);
  b = good;
  b.odd[4] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(refusal(b), "denoise: the 'odd' buffer has a non-finite value (nan) at pixel (1, 0)");
  b = good;
  b.depth[5] = std::numeric_limits<float>::infinity();
  EXPECT_EQ(refusal(b), "denoise: the 'depth' buffer has a non-finite value (inf) at pixel (2, 1)");
  b = good;
  b.color[0] = -std::numeric_limits<float>::infinity();
  EXPECT_NE(refusal(b).find("'color'"), std::string::npos);
  b = good;
  b.width = 0;
  EXPECT_NE(refusal(b).find("0 x 2"), std::string::npos);
  EXPECT_EQ(refusal(good), "(accepted)");
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: half-buffers differing past about 2^64 (a light of 1e20) overflowed the
// variance, every weight became 0 and the image was denoised to black. Colours past 2^40
// are denoised as their image scaled by a power of two.
TEST(Denoiser, ColoursPastFloatsSquaresAreDenoisedAsTheirScaledImage) {
  const Scene s = make_scene(64, 48);
  const DenoiseBuffers b = noisy(s, 0.5f, 7);
  const std::vector<float> plain = denoise(b);
  DenoiseBuffers huge = b;
  const float scale = 0x1p70f;  // 1.2e21
  for (std::vector<float>* v : {&huge.color, &huge.even, &huge.odd})
    for (float& x : *v) x *= scale;
  const std::vector<float> out = denoise(huge);
  // Exactly the image brought to 2^40 denoised, scaled back.
  float largest = 0;
  for (const std::vector<float>* v : {&huge.color, &huge.even, &huge.odd})
    for (const float x : *v) largest = std::max(largest, std::fabs(x));
  int e = 0;
  std::frexp(largest, &e);
  const float down = std::ldexp(1.0f, 40 - e);
  DenoiseBuffers in_range = huge;
  for (std::vector<float>* v : {&in_range.color, &in_range.even, &in_range.odd})
    for (float& x : *v) x *= down;
  std::vector<float> want = denoise(in_range);
  for (float& x : want) x /= down;
  EXPECT_EQ(out, want);
  // And it denoises as the image did as it was (not the same bits: the filters' floors
  // are absolute).
  std::vector<float> back = out;
  for (float& x : back) x /= scale;
  const std::vector<bool> all(s.region.size(), true);
  const double noisy_error = rel_mse(b.color, s.truth, all), plain_error = rel_mse(plain, s.truth, all);
  EXPECT_LT(rel_mse(back, s.truth, all), 1.5 * plain_error);
  EXPECT_LT(plain_error * 4, noisy_error);
}

// Found by audit: a hostile half-buffer (-3e38 at one pixel) pulled 48 pixels of an image
// whose colours are all positive below zero.
TEST(Denoiser, AHostileHalfBufferCannotTurnAPositiveImageNegative) {
  const Scene s = make_scene(64, 48);
  DenoiseBuffers b = fireflies(s, 4, 5);
  b.odd[3 * (20 * 64 + 30) + 1] = -3e38f;
  const std::vector<float> out = denoise(b);
  for (const float x : out) ASSERT_TRUE(std::isfinite(x));
  EXPECT_GE(*std::min_element(out.begin(), out.end()), 0.f);
}

// The memory the denoiser holds counts its padded grid: a one-pixel-wide band of 2^20 rows
// takes each plane 80 floats wide (6 GB where the bands were sized by pixels alone).
TEST(Denoiser, ItsWorkingMemoryCountsThePaddedGrid) {
  EXPECT_GE(denoise_working_bytes(1, 1 << 20), uint64_t(17) * 80 * (1 << 20) * sizeof(float));
  EXPECT_LT(denoise_working_bytes(480, 360), uint64_t(64) << 20);
}

}  // namespace
}  // namespace tessera
