#include "core/io/image_io.h"

#include <stb/stb_image_write.h>

#include <cmath>
#include <cstdio>
#include <mutex>
#include <stdexcept>

#include "core/io/exr_writer.h"
#include "core/io/files.h"
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
  std::vector<uint8_t> rgb(size_t(w) * h * 3);
  for (size_t i = 0; i < size_t(w) * h; ++i) {
    rgb[3 * i] = srgb_byte(r[i] * scale);
    rgb[3 * i + 1] = srgb_byte(g[i] * scale);
    rgb[3 * i + 2] = srgb_byte(b[i] * scale);
  }
  std::string out;
  auto append = [](void* context, void* data, int size) {
    static_cast<std::string*>(context)->append(static_cast<const char*>(data), size_t(size));
  };
  // stb's compression level is a global: set and use it under one lock.
  static std::mutex stb_mu;
  std::lock_guard<std::mutex> lock(stb_mu);
  stbi_write_png_compression_level = fast ? 1 : 8;
  if (!stbi_write_png_to_func(append, &out, w, h, 3, rgb.data(), w * 3)) throw std::runtime_error("cannot encode PNG");
  return out;
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
  const size_t n = size_t(film.width()) * film.height();
  std::vector<float> r(n), g(n), b(n);
  for (size_t i = 0; i < n; ++i) {
    const Rgb m = film.pixels()[i].mean();
    r[i] = m.r;
    g[i] = m.g;
    b[i] = m.b;
  }
  std::string bytes;
  try {
    bytes = encode_png(film.width(), film.height(), r.data(), g.data(), b.data(), fast, scale);
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
