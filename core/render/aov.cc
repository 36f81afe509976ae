#include "core/render/aov.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "core/render/settings.h"

namespace tessera {

namespace {

constexpr std::pair<const char*, uint32_t> kNames[] = {{"alpha", kAovAlpha},   {"albedo", kAovAlbedo},
                                                       {"normal", kAovNormal}, {"depth", kAovDepth},
                                                       {"id", kAovId},         {"halves", kAovHalves}};

int64_t fixed(float v, double unit) { return int64_t(std::llround(double(v) * unit)); }

}  // namespace

uint32_t parse_aovs(const std::string& list) {
  uint32_t bits = 0;
  std::stringstream ss(list);
  std::string name;
  while (std::getline(ss, name, ',')) {
    name.erase(0, name.find_first_not_of(" \t"));
    name.erase(name.find_last_not_of(" \t") + 1);
    if (name.empty()) continue;
    if (name == "all" || name == "denoising") {
      bits |= name == "all" ? kAovAll : kAovDenoising;
      continue;
    }
    const auto* it = std::find_if(std::begin(kNames), std::end(kNames), [&](const auto& e) { return name == e.first; });
    if (it == std::end(kNames))
      throw SettingsError("--aov",
                          "'" + name + "' is not an AOV (alpha, albedo, normal, depth, id, halves, all or denoising)");
    bits |= it->second;
  }
  return bits;
}

std::string aov_names(uint32_t aovs) {
  std::string out;
  for (const auto& [name, bit] : kNames)
    if (aovs & bit) {
      if (!out.empty()) out += ',';
      out += name;
    }
  return out;
}

void AovSums::add_sample(const FirstHit& h, uint32_t sample) {
  ++n;
  if (!h.hit) return;
  ++hits;
  const float a[3] = {h.albedo.r, h.albedo.g, h.albedo.b}, nv[3] = {h.normal.x, h.normal.y, h.normal.z};
  for (int c = 0; c < 3; ++c) {
    albedo[c] += fixed(std::clamp(std::isfinite(a[c]) ? a[c] : 0.0f, 0.0f, 1.0f), kUnit);
    normal[c] += fixed(std::clamp(std::isfinite(nv[c]) ? nv[c] : 0.0f, -1.0f, 1.0f), kUnit);
  }
  const double d = std::isfinite(h.distance) ? std::clamp(double(h.distance), 0.0, kMaxDistance) : kMaxDistance;
  distance += int64_t(std::llround(d * kDistanceUnit));
  if (sample < id_sample) {
    id_sample = sample;
    id = h.material;
  }
}

void AovSums::add(const AovSums& o) {
  n += o.n;
  hits += o.hits;
  for (int c = 0; c < 3; ++c) {
    albedo[c] += o.albedo[c];
    normal[c] += o.normal[c];
  }
  distance += o.distance;
  if (o.id_sample < id_sample) {
    id_sample = o.id_sample;
    id = o.id;
  }
}

bool AovSums::operator==(const AovSums& o) const {
  return n == o.n && hits == o.hits && std::equal(albedo, albedo + 3, o.albedo) &&
         std::equal(normal, normal + 3, o.normal) && distance == o.distance && id == o.id && id_sample == o.id_sample;
}

bool AovSums::plausible(uint32_t max_samples) const {
  if (n > max_samples || hits > n) return false;
  const double h = double(hits);
  for (int c = 0; c < 3; ++c) {
    if (albedo[c] < 0 || double(albedo[c]) > h * kUnit) return false;
    if (double(normal[c]) < -h * kUnit || double(normal[c]) > h * kUnit) return false;
  }
  if (distance < 0 || double(distance) > h * kMaxDistance * kDistanceUnit) return false;
  if ((id == kNoId) != (id_sample == kNoId) || (hits == 0 && id != kNoId)) return false;
  return true;
}

void AovFilm::clear(const Rect& rect) {
  for (int y = 0; y < rect.h; ++y)
    std::fill_n(pixels_.begin() + ptrdiff_t(size_t(rect.y - window_.y + y) * window_.w + size_t(rect.x - window_.x)),
                rect.w, AovSums{});
}

void AovFilm::add_tile(const Rect& rect, const std::vector<AovSums>& sums) {
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x)
      pixels_[size_t(rect.y - window_.y + y) * window_.w + size_t(rect.x - window_.x + x)].add(
          sums[size_t(y) * rect.w + x]);
}

AovPixel aov_pixel(const AovSums& s) {
  AovPixel p;
  if (s.n) p.alpha = float(double(s.hits) / s.n);
  if (s.hits) {
    const double k = 1.0 / (double(s.hits) * AovSums::kUnit);
    for (int c = 0; c < 3; ++c) {
      p.albedo[c] = float(double(s.albedo[c]) * k);
      p.normal[c] = float(double(s.normal[c]) * k);
    }
    p.depth = float(double(s.distance) / (double(s.hits) * AovSums::kDistanceUnit));
  }
  if (s.id != AovSums::kNoId) p.id = float(s.id);
  return p;
}

std::vector<std::string> aov_channels(uint32_t aovs) {
  std::vector<std::string> out;
  if (aovs & kAovAlpha) out.push_back("A");
  if (aovs & kAovAlbedo)
    for (const char* c : {"albedo.R", "albedo.G", "albedo.B"}) out.push_back(c);
  if (aovs & kAovNormal)
    for (const char* c : {"normal.X", "normal.Y", "normal.Z"}) out.push_back(c);
  if (aovs & kAovDepth) out.push_back("depth.Z");
  if (aovs & kAovId) out.push_back("id.V");
  return out;
}

void aov_channel_values(const AovSums& s, uint32_t aovs, float* out) {
  const AovPixel p = aov_pixel(s);
  if (aovs & kAovAlpha) *out++ = p.alpha;
  if (aovs & kAovAlbedo) out = std::copy(p.albedo, p.albedo + 3, out);
  if (aovs & kAovNormal) out = std::copy(p.normal, p.normal + 3, out);
  if (aovs & kAovDepth) *out++ = p.depth;
  if (aovs & kAovId) *out = p.id;
}

}  // namespace tessera
