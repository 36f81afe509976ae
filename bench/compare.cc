// Error of an image against a reference, as JSON:
//   rmse     sqrt(mean over pixels and channels of (x - ref)^2)
//   relmse   mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01)
//   regions  mean RGB of each named rectangle, in both images (--regions FILE.json, a map
//            of name -> [x, y, w, h] in pixels, row 0 at the top), the relmse over its
//            pixels, and the standard error of IMAGE's mean luminance there when IMAGE has
//            a variance channel; pixels not finite in both images are left out (counted
//            as the region's "nonfinite")
//   identical  every channel of both images (R, G, B, spp, variance) equal bit for bit
// Usage: tessera_compare IMAGE.exr REFERENCE.exr [--regions FILE.json]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>

#include "core/io/image_io.h"

using namespace tessera;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: tessera_compare IMAGE.exr REFERENCE.exr [--regions FILE.json]\n");
    return 2;
  }
  try {
    const ExrImage a = read_exr(argv[1]), r = read_exr(argv[2]);
    if (a.width != r.width || a.height != r.height) throw std::runtime_error("image sizes differ");
    if (a.x0 != r.x0 || a.y0 != r.y0)  // (the same pixels elsewhere in the frame are not the same image)
      throw std::runtime_error("the images' data windows start at different pixels: (" + std::to_string(a.x0) + ", " +
                               std::to_string(a.y0) + ") against (" + std::to_string(r.x0) + ", " +
                               std::to_string(r.y0) + ")");
    const char* ch[3] = {"R", "G", "B"};
    for (const char* c : ch)
      for (const auto& [image, name] : {std::pair{&a, argv[1]}, std::pair{&r, argv[2]}})
        if (!image->channels.count(c)) throw std::runtime_error(std::string(name) + " has no channel " + c);
    double se = 0, rel = 0, n = 0, nonfinite = 0;
    for (int c = 0; c < 3; ++c) {
      const auto &x = a.channels.at(ch[c]), &y = r.channels.at(ch[c]);
      for (size_t i = 0; i < x.size(); ++i) {
        if (!std::isfinite(x[i]) || !std::isfinite(y[i])) {  // (either image's: the other's pixels are compared)
          ++nonfinite;
          continue;
        }
        const double d = double(x[i]) - double(y[i]);
        se += d * d;
        rel += d * d / (double(y[i]) * double(y[i]) + 0.01);
        ++n;
      }
    }
    bool identical = a.channels.size() == r.channels.size();
    for (const auto& [name, values] : a.channels) {
      auto other = r.channels.find(name);
      identical = identical && other != r.channels.end() && values.size() == other->second.size() &&
                  std::memcmp(values.data(), other->second.data(), values.size() * sizeof(float)) == 0;
    }
    if (n == 0) throw std::runtime_error("no pixel is finite in both images: nothing to compare");
    nlohmann::json out{
        {"rmse", std::sqrt(se / n)}, {"relmse", rel / n}, {"nonfinite", nonfinite}, {"identical", identical}};
    for (int i = 3; i + 1 < argc; ++i) {
      if (std::string(argv[i]) != "--regions") continue;
      std::ifstream f(argv[i + 1]);
      const nlohmann::json regions = nlohmann::json::parse(f);
      for (const auto& [name, rect] : regions.items()) {
        if (!rect.is_array() || rect.size() != 4 ||
            !std::all_of(rect.begin(), rect.end(), [](const nlohmann::json& v) { return v.is_number_integer(); }))
          throw std::runtime_error("region '" + name + "' is not [x, y, w, h] in whole pixels");
        const long long x0 = rect[0], y0 = rect[1], w = rect[2], h = rect[3];
        if (x0 < 0 || y0 < 0 || w < 1 || h < 1 || x0 + w > a.width || y0 + h > a.height)  // (no overflow: 64 bits)
          throw std::runtime_error("region '" + name + "' is not inside the image");
        // Pixels finite in both images, as over the whole image.
        double sa[3] = {}, sr[3] = {}, var = 0, region_rel = 0, finite = 0, region_nonfinite = 0;
        const auto v = a.channels.find("variance");
        for (long long y = y0; y < y0 + h; ++y)
          for (long long x = x0; x < x0 + w; ++x) {
            const size_t p = size_t(y) * size_t(a.width) + size_t(x);
            double xi[3], yi[3];
            bool ok = true;
            for (int c = 0; c < 3; ++c) {
              xi[c] = a.channels.at(ch[c])[p];
              yi[c] = r.channels.at(ch[c])[p];
              ok = ok && std::isfinite(xi[c]) && std::isfinite(yi[c]);
            }
            if (!ok) {
              ++region_nonfinite;
              continue;
            }
            for (int c = 0; c < 3; ++c) {
              sa[c] += xi[c];
              sr[c] += yi[c];
              region_rel += (xi[c] - yi[c]) * (xi[c] - yi[c]) / (yi[c] * yi[c] + 0.01);
            }
            ++finite;
            if (v != a.channels.end() && std::isfinite(v->second[p])) var += v->second[p];
          }
        if (finite == 0) throw std::runtime_error("region '" + name + "' has no pixel finite in both images");
        const double k = finite;
        out["regions"][name] = {{"image", {sa[0] / k, sa[1] / k, sa[2] / k}},
                                {"reference", {sr[0] / k, sr[1] / k, sr[2] / k}},
                                {"relmse", region_rel / (3 * k)},
                                {"nonfinite", region_nonfinite}};
        // The standard error of the image's mean luminance over the region, from its
        // per-pixel variance channel (a Tessera EXR), when it has one.
        if (v != a.channels.end()) out["regions"][name]["image_luminance_stderr"] = std::sqrt(var) / k;
      }
    }
    std::printf("%s\n", out.dump().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera_compare: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
