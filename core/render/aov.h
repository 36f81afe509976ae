// AOVs (arbitrary output variables): what the camera ray's first hit saw, for compositing
// and for the denoiser, taken from the camera samples already traced (no extra rays) and
// only when asked for (--aov): coverage (alpha), albedo, shading normal, depth and the
// material's index.
//
// Their sums are fixed-point integers, not doubles: integer addition is associative, so a
// pixel's AOVs are the same bits whatever order and grouping its samples are added in
// (passes, runs of passes, tiles, workers), without the pass-order discipline the film's
// doubles need. The quantisation (2^-24 of an albedo or normal component, 2^-16 of a
// distance unit) is far below what a float channel in the EXR keeps.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/math/rect.h"
#include "core/math/vec.h"

namespace tessera {

// Which AOVs a render writes: a bit set.
enum Aov : uint32_t {
  kAovAlpha = 1u << 0,
  kAovAlbedo = 1u << 1,
  kAovNormal = 1u << 2,
  kAovDepth = 1u << 3,
  kAovId = 1u << 4,
  // The half-buffers: the means of each pixel's even- and odd-numbered samples (layers
  // even.R/G/B and odd.R/G/B), two independent estimates of the image for the denoiser.
  // Not an AovSums field: a film's second plane of sums (film.h), added in pass order.
  kAovHalves = 1u << 5,
};
// The compositing passes ("all").
constexpr uint32_t kAovAll = kAovAlpha | kAovAlbedo | kAovNormal | kAovDepth | kAovId;
// What the denoiser reads besides the image ("denoising", as Blender's "Denoising Data").
constexpr uint32_t kAovDenoising = kAovAlbedo | kAovNormal | kAovDepth | kAovHalves;
constexpr uint32_t kAovKnown = kAovAll | kAovHalves;

// "albedo,normal,depth,alpha,id,halves" (any of them, in any order; "all" the first five;
// "denoising" albedo, normal, depth and halves; "" none) -> bits. Throws
// SettingsError("--aov", ...) naming an unknown one.
uint32_t parse_aovs(const std::string& list);
std::string aov_names(uint32_t aovs);  // the list parse_aovs reads back

// What one camera sample's first hit saw: filled by Integrator::radiance when asked.
struct FirstHit {
  bool hit = false;    // the camera ray met a surface (else: the environment or nothing)
  float distance = 0;  // from the ray's origin (the camera, or its lens) to the hit
  Vec3 normal;         // shading normal, world space, turned toward the camera
  Rgb albedo;          // the surface's reflectance there (base colour, textures applied), in [0, 1]
  uint32_t material = 0;
};

// One pixel's AOV sums over its samples.
struct AovSums {
  static constexpr double kUnit = double(1 << 24);          // per albedo or normal component
  static constexpr double kDistanceUnit = double(1 << 16);  // per scene unit of distance
  static constexpr double kMaxDistance = double(1 << 20);   // distances are clamped here (no overflow at any spp)
  static constexpr uint32_t kNoId = UINT32_MAX;

  uint32_t n = 0;                 // samples
  uint32_t hits = 0;              // samples that met a surface: alpha = hits / n
  int64_t albedo[3] = {0, 0, 0};  // over hits, x kUnit
  int64_t normal[3] = {0, 0, 0};  // over hits, x kUnit
  int64_t distance = 0;           // over hits, x kDistanceUnit
  // The material of the pixel's hit sample with the smallest index (kNoId: none yet): the
  // same whatever the order samples are added in.
  uint32_t id = kNoId, id_sample = kNoId;

  void add_sample(const FirstHit& h, uint32_t sample);
  // Whether these sums could come from rendering at most `max_samples` samples: hits <= n
  // <= max_samples, every sum within what that many hits can reach, an id with the sample
  // it came from. What a worker sends is checked with it before it is added (no overflow).
  bool plausible(uint32_t max_samples) const;
  void add(const AovSums& o);
  bool operator==(const AovSums& o) const;
};

// A frame's AOV sums, as Film holds the radiance's: (x, y) relative to the window.
class AovFilm {
 public:
  AovFilm() = default;
  explicit AovFilm(Rect window) : window_(window), pixels_(size_t(window.area())) {}
  bool empty() const { return pixels_.empty(); }
  const Rect& window() const { return window_; }
  const AovSums& at(int x, int y) const { return pixels_[size_t(y) * window_.w + x]; }
  const std::vector<AovSums>& pixels() const { return pixels_; }
  // Adds a tile's sums (rect in image coordinates, sums row-major over the rect).
  void add_tile(const Rect& rect, const std::vector<AovSums>& sums);
  void clear(const Rect& rect);  // back to zero (a tile rendered again)
  AovSums* row(int y) { return pixels_.data() + size_t(y) * window_.w; }

 private:
  Rect window_{};
  std::vector<AovSums> pixels_;
};

// A pixel's AOVs as the EXR stores them (the one conversion from sums): alpha, mean albedo
// and normal over its hits, mean distance over hits (kBackgroundDepth where none), the id
// (-1 where none).
struct AovPixel {
  static constexpr float kBackgroundDepth = 1e10f;  // Blender's Z pass of the background
  float alpha = 0;
  float albedo[3] = {0, 0, 0};
  float normal[3] = {0, 0, 0};
  float depth = kBackgroundDepth;
  float id = -1;
};
AovPixel aov_pixel(const AovSums& s);

// The EXR channels of each AOV in AovSums, in the names Blender's and Nuke's readers expect
// (docs/aov.md); the half-buffers' are kHalfChannels.
std::vector<std::string> aov_channels(uint32_t aovs);
inline constexpr const char* kHalfChannels[6] = {"even.R", "even.G", "even.B", "odd.R", "odd.G", "odd.B"};
// A pixel's values of those channels, in that order, into out[0 .. aov_channels(aovs).size()).
void aov_channel_values(const AovSums& s, uint32_t aovs, float* out);

}  // namespace tessera
