// Reading float images: OpenEXR files (every channel by name) and the RGB environment maps
// lights are made of (.exr or Radiance .hdr). In the scene layer because an environment is
// scene data; writing images is core/io's.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/math/vec.h"

namespace tessera {

struct ExrImage {
  int width = 0, height = 0;
  int x0 = 0, y0 = 0;                                  // the data window's first pixel
  std::map<std::string, std::vector<float>> channels;  // row-major, row 0 at the top
  std::map<std::string, std::string> metadata;         // the file's string attributes
};
// Throws std::runtime_error naming the path. Images over kMaxEnvironmentTexels are refused
// from the header, before anything is allocated, and so are channels to read taking more
// than kMaxExrReadBytes together (a 1 KB header declaring 40 channels of 2^26 pixels asked
// for 10 GB). `only`: those channels alone (the others not read), where given.
constexpr uint64_t kMaxExrReadBytes = uint64_t(4) << 30;
ExrImage read_exr(const std::string& path, const std::set<std::string>& only = {});

// An RGB image in linear radiance, row 0 at the top.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<Rgb> texels;
};
constexpr long long kMaxEnvironmentTexels = 1LL << 26;  // 64 M texels, 768 MB as floats
// A lat-long environment map: .exr (channels R, G, B by name; Y alone as grey) or .hdr
// (Radiance RGBE). Throws std::runtime_error naming the file and the problem: unreadable,
// unknown extension, too large, or a texel that is negative, NaN or infinite.
RgbImage read_environment_image(const std::string& path);

}  // namespace tessera
