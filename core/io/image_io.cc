#include "core/io/image_io.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/io/exr_writer.h"
#include "core/io/files.h"
#include "core/io/png_encoder.h"
#include "core/math/float_math.h"

namespace tessera {
namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i)
    if (std::tolower(uint8_t(s[s.size() - suffix.size() + i])) != suffix[i]) return false;
  return true;
}

}  // namespace

uint8_t srgb_byte(float v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * fm::pow(v, 1 / 2.4f) - 0.055f;
  return uint8_t(std::lround(s * 255));
}

void write_exr(const std::string& path, const Film& film, const ImageMetadata& metadata, bool fast, const AovFilm* aovs,
               uint32_t aov_bits, const Rect& frame) {
  const bool with_aovs = aovs && !aovs->empty() && aov_bits;
  ExrWriter out(path, film.window(), frame.area() > 0 ? frame : film.window(), metadata, !fast,
                with_aovs ? aov_bits : 0);
  if (film.height() > 0)
    out.write_rows(film.pixels().data(), film.height(), with_aovs ? aovs->pixels().data() : nullptr,
                   with_aovs && film.halves() ? film.odd().data() : nullptr);
  out.commit();
}

std::string encode_png(int w, int h, const float* r, const float* g, const float* b, bool fast, float scale) {
  PngEncoder png(w, h, fast);
  for (size_t y = 0; y < size_t(h); ++y) png.write_row(r + y * w, g + y * w, b + y * w, scale);
  return png.finish();
}

float exposure_scale(const ImageMetadata& metadata) {
  auto it = metadata.find(kExposureAttribute);
  if (it == metadata.end()) it = metadata.find(kExposureFileAttribute);
  if (it == metadata.end()) return 1;
  try {
    size_t used = 0;
    const float ev = std::stof(it->second, &used);
    if (used != it->second.size() || !std::isfinite(ev) || std::fabs(ev) > 64) return 1;
    return fm::pow(2.0f, ev);  // exact for whole EVs
  } catch (const std::exception&) {
    return 1;
  }
}

std::string exposure_text(float ev) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9g", double(ev));
  return buf;
}

void write_png(const std::string& path, const Film& film, bool fast, float scale) {
  const size_t w = size_t(film.width());
  std::vector<float> r(w), g(w), b(w);  // a row's means at a time
  std::string bytes;
  try {
    PngEncoder png(film.width(), film.height(), fast);
    for (int y = 0; y < film.height(); ++y) {
      for (size_t x = 0; x < w; ++x) {
        const Rgb m = film.pixels()[size_t(y) * w + x].mean();
        r[x] = m.r;
        g[x] = m.g;
        b[x] = m.b;
      }
      png.write_row(r.data(), g.data(), b.data(), scale);
    }
    bytes = png.finish();
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(path + ": " + e.what());
  }
  write_file_atomic(path, bytes);
}

std::string encode_png(const ExrImage& img) {
  return encode_png(img.width, img.height, img.channels.at("R").data(), img.channels.at("G").data(),
                    img.channels.at("B").data(), false, exposure_scale(img.metadata));
}

bool is_exr_path(const std::string& path) { return ends_with(path, ".exr"); }

void write_image(const std::string& path, const Film& film, const ImageMetadata& metadata, const AovFilm* aovs,
                 uint32_t aov_bits, const Rect& frame) {
  if (ends_with(path, ".exr")) return write_exr(path, film, metadata, false, aovs, aov_bits, frame);
  if (ends_with(path, ".png")) return write_png(path, film, false, exposure_scale(metadata));
  throw std::runtime_error(path + ": unknown image format (use .exr or .png)");
}

}  // namespace tessera
