#include "core/denoise/denoise_exr.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <chrono>
#include <cstdio>
#include <stdexcept>

#include "core/io/files.h"

namespace tessera {

const std::vector<std::string> kDenoiseChannels = {"even.R",   "even.G",   "even.B",   "odd.R",    "odd.G",
                                                   "odd.B",    "albedo.R", "albedo.G", "albedo.B", "normal.X",
                                                   "normal.Y", "normal.Z", "depth.Z"};

namespace {

constexpr const char* kDenoiserName = "tessera first-order regression (core/denoise/denoiser.h)";

// Interleaves three planes of `image` into RGB triples.
std::vector<float> interleave(const ExrImage& image, const std::string& a, const std::string& b, const std::string& c) {
  const std::vector<float>* planes[3] = {&image.channels.at(a), &image.channels.at(b), &image.channels.at(c)};
  const size_t n = size_t(image.width) * size_t(image.height);
  std::vector<float> out(3 * n);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) out[3 * i + k] = (*planes[k])[i];
  return out;
}

}  // namespace

DenoiseBuffers denoise_buffers(const ExrImage& image, const std::string& what) {
  const bool again = image.channels.count(kNoisyChannels[0]) != 0;  // denoised before: start from the noisy image
  std::vector<std::string> needed = kDenoiseChannels;
  if (again)
    needed.insert(needed.end(), std::begin(kNoisyChannels), std::end(kNoisyChannels));
  else
    needed.insert(needed.end(), {"R", "G", "B"});
  std::string missing;
  for (const std::string& c : needed)
    if (!image.channels.count(c)) missing += (missing.empty() ? "" : ", ") + c;
  if (!missing.empty())
    throw std::runtime_error(what + ": cannot denoise: no " + missing +
                             " channel(s); render with --denoise or --aov denoising (albedo, normal, depth, halves)");
  DenoiseBuffers in;
  in.width = image.width;
  in.height = image.height;
  in.color = again ? interleave(image, kNoisyChannels[0], kNoisyChannels[1], kNoisyChannels[2])
                   : interleave(image, "R", "G", "B");
  in.even = interleave(image, "even.R", "even.G", "even.B");
  in.odd = interleave(image, "odd.R", "odd.G", "odd.B");
  in.albedo = interleave(image, "albedo.R", "albedo.G", "albedo.B");
  in.normal = interleave(image, "normal.X", "normal.Y", "normal.Z");
  in.depth = image.channels.at("depth.Z");
  return in;
}

DenoiseReport denoise_exr(const std::string& in_path, const std::string& out_path, const DenoiseOptions& options) {
  ExrImage image = read_exr(in_path);
  const DenoiseBuffers in = denoise_buffers(image, in_path);
  DenoiseReport report;
  report.width = image.width;
  report.height = image.height;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<float> rgb;
  try {
    rgb = denoise(in, options);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(in_path + ": cannot denoise: " + e.what());
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  // The noisy image moves to noisy.*, unless it is there already (denoised again).
  const size_t n = size_t(image.width) * size_t(image.height);
  for (int c = 0; c < 3; ++c) {
    std::vector<float>& plane = image.channels[std::string(1, "RGB"[c])];
    if (!image.channels.count(kNoisyChannels[c])) image.channels[kNoisyChannels[c]] = plane;
    for (size_t i = 0; i < n; ++i) plane[i] = rgb[3 * i + size_t(c)];
  }

  Imf::Header header(image.width, image.height);
  header.compression() = Imf::ZIP_COMPRESSION;
  image.metadata["tessera/denoiser"] = kDenoiserName;
  for (const auto& [key, value] : image.metadata) header.insert(key, Imf::StringAttribute(value));
  Imf::FrameBuffer fb;
  for (auto& [name, plane] : image.channels) {
    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(plane.data()), sizeof(float),
                               sizeof(float) * size_t(image.width)));
  }
  const std::string tmp = out_path + ".tmp";
  try {
    Imf::OutputFile file(tmp.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(image.height);
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    throw std::runtime_error(out_path + ": cannot write EXR: " + e.what());
  }
  commit_file(tmp, out_path);
  return report;
}

}  // namespace tessera
