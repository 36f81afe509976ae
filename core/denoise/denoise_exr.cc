#include "core/denoise/denoise_exr.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfMultiPartInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfTestFile.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <stdexcept>

#include "core/io/files.h"
#include "core/io/interrupt_cleanup.h"

namespace tessera {

const std::vector<std::string> kDenoiseChannels = {"even.R",   "even.G",   "even.B",   "odd.R",    "odd.G",
                                                   "odd.B",    "albedo.R", "albedo.G", "albedo.B", "normal.X",
                                                   "normal.Y", "normal.Z", "depth.Z"};

namespace {

constexpr const char* kDenoiserName = "tessera first-order regression (core/denoise/denoiser.h)";
using Planes = std::map<std::string, std::vector<float>>;
namespace fs = std::filesystem;

// A band is denoised with this many rows more on each side: the denoiser's reach, exactly
// (DenoiseExr.BandsOfRowsGiveTheWholeImagesBits fails with one row less).
constexpr int kHalo = kDenoiseReach;
constexpr uint64_t kBandBytes = uint64_t(1) << 28;     // a band's memory, about (the bands' bits are the same)
constexpr uint64_t kMaxBandBytes = uint64_t(1) << 30;  // and at most

// Interleaves three planes into RGB triples.
std::vector<float> interleave(const Planes& planes, const std::string& a, const std::string& b, const std::string& c) {
  const std::vector<float>* p[3] = {&planes.at(a), &planes.at(b), &planes.at(c)};
  const size_t n = p[0]->size();
  std::vector<float> out(3 * n);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) out[3 * i + k] = (*p[k])[i];
  return out;
}

// The channels the denoiser reads, given which exist; throws naming `what` and the missing.
bool check_channels(const std::vector<std::string>& present, const std::string& what) {
  auto has = [&](const std::string& c) { return std::find(present.begin(), present.end(), c) != present.end(); };
  const bool again = has(kNoisyChannels[0]);  // denoised before: start from the noisy image
  std::vector<std::string> needed = kDenoiseChannels;
  needed.insert(needed.end(), {"R", "G", "B"});  // (replaced by the result; once more, read from noisy.*)
  if (again) needed.insert(needed.end(), std::begin(kNoisyChannels), std::end(kNoisyChannels));
  std::string missing;
  for (const std::string& c : needed)
    if (!has(c)) missing += (missing.empty() ? "" : ", ") + c;
  if (!missing.empty())
    throw std::runtime_error(what + ": cannot denoise: no " + missing +
                             " channel(s); render with --denoise or --aov denoising (albedo, normal, depth, halves)");
  return again;
}

DenoiseBuffers buffers_of(const Planes& planes, int width, int rows, int first_row, int first_column, bool again) {
  DenoiseBuffers in;
  in.width = width;
  in.height = rows;
  in.first_row = first_row;
  in.first_column = first_column;
  in.color = again ? interleave(planes, kNoisyChannels[0], kNoisyChannels[1], kNoisyChannels[2])
                   : interleave(planes, "R", "G", "B");
  in.even = interleave(planes, "even.R", "even.G", "even.B");
  in.odd = interleave(planes, "odd.R", "odd.G", "odd.B");
  in.albedo = interleave(planes, "albedo.R", "albedo.G", "albedo.B");
  in.normal = interleave(planes, "normal.X", "normal.Y", "normal.Z");
  in.depth = planes.at("depth.Z");
  return in;
}

// A slice addressing `plane` (rows of `width` floats) as image rows from `first_row` on,
// with the image's origin at (x0, y0).
// An integer channel (an object id, say) is carried as its bits in the plane's floats.
Imf::Slice slice(std::vector<float>& plane, int width, long long first_row, long long x0, long long y0,
                 Imf::PixelType type) {
  static_assert(sizeof(float) == sizeof(uint32_t));
  char* base =
      reinterpret_cast<char*>(plane.data()) - ptrdiff_t((x0 + (y0 + first_row) * width) * ptrdiff_t(sizeof(float)));
  return Imf::Slice(type == Imf::UINT ? Imf::UINT : Imf::FLOAT, base, sizeof(float), sizeof(float) * size_t(width));
}

}  // namespace

DenoiseReport denoise_exr(const std::string& in_path, const std::string& out_path, const DenoiseOptions& options) {
  const std::string tmp = temporary_path(out_path);
  {
    // The output is written to OUT.tmp first: were that the input, the input would be
    // truncated before it was read, then removed as the failed output's.
    std::error_code ec;
    if (fs::equivalent(in_path, tmp, ec))
      throw std::runtime_error(in_path + ": cannot denoise into " + out_path + ": the input is the output's " +
                               "temporary file (" + tmp + "); name another output");
  }
  std::unique_ptr<Imf::InputFile> input;
  std::vector<std::string> channels;
  std::map<std::string, Imf::PixelType> types;
  int width = 0, height = 0;
  Imath::Box2i dw;
  try {
    if (Imf::isMultiPartOpenExrFile(in_path.c_str())) {
      const int parts = Imf::MultiPartInputFile(in_path.c_str()).parts();
      if (parts > 1)
        throw std::runtime_error("it has " + std::to_string(parts) +
                                 " parts; the denoiser reads single-part images (its output would lose the rest)");
    }
    input = std::make_unique<Imf::InputFile>(in_path.c_str());
    dw = input->header().dataWindow();
    const long long w = (long long)dw.max.x - dw.min.x + 1, h = (long long)dw.max.y - dw.min.y + 1;
    if (w < 1 || h < 1 || w > (1 << 20) || h > (1 << 20))
      throw std::runtime_error(std::to_string(w) + " x " + std::to_string(h) + " pixels is beyond the limit");
    width = int(w);
    height = int(h);
    for (auto it = input->header().channels().begin(); it != input->header().channels().end(); ++it) {
      channels.push_back(it.name());
      types[it.name()] = it.channel().type;
    }
  } catch (const std::exception& e) {
    throw std::runtime_error(in_path + ": cannot read EXR: " + e.what());
  }
  const bool again = check_channels(channels, in_path);
  for (const auto& [name, type] : types)
    if (type == Imf::UINT &&
        (name == "R" || name == "G" || name == "B" ||
         std::find(kDenoiseChannels.begin(), kDenoiseChannels.end(), name) != kDenoiseChannels.end() ||
         std::find(std::begin(kNoisyChannels), std::end(kNoisyChannels), name) != std::end(kNoisyChannels)))
      throw std::runtime_error(in_path + ": cannot denoise: channel " + name + " holds integers, not colours");
  DenoiseReport report;
  report.width = width;
  report.height = height;

  // The output: the input's header (its data and display windows, every attribute), its
  // channels as they were but R, G and B, which hold the result, and the noisy image's
  // (noisy.* unless there already), written in scan lines.
  Imf::Header header = input->header();
  for (const char* part_only : {"tiles", "type", "name", "chunkCount", "version"})
    if (header.find(part_only) != header.end()) header.erase(part_only);
  header.compression() = Imf::ZIP_COMPRESSION;
  header.lineOrder() = Imf::INCREASING_Y;
  header.insert("tessera/denoiser", Imf::StringAttribute(kDenoiserName));
  header.channels() = Imf::ChannelList();
  std::vector<std::string> out_channels = channels;
  if (!again) out_channels.insert(out_channels.end(), std::begin(kNoisyChannels), std::end(kNoisyChannels));
  for (const std::string& c : out_channels) {
    const bool result = c == "R" || c == "G" || c == "B" || !types.count(c);
    header.channels().insert(c, Imf::Channel(result ? Imf::FLOAT : types[c]));
  }

  // A band of every channel, with its halo, and what the denoiser holds for it, in memory at
  // once: about kBandBytes, bounded, naming the input (40 channels 2^20 wide asked for
  // gigabytes and failed as the output's "cannot write"; a 1 x 2^20 image took 6 GB on the
  // denoiser's padded grid).
  const auto band_bytes = [&](int rows) {
    const int r = std::min(height, rows + 2 * kHalo);
    return denoise_working_bytes(width, r) + uint64_t(out_channels.size()) * uint64_t(width) * uint64_t(r) * 4;
  };
  int band = options.band_rows;
  if (band <= 0) {  // the most rows within kBandBytes, at least 16
    band = 16;
    for (int step = 1 << 20; step > 0; step /= 2)
      if (band + step <= height && band_bytes(band + step) <= kBandBytes) band += step;
  }
  if (band_bytes(band) > kMaxBandBytes)
    throw std::runtime_error(in_path + ": " + std::to_string(channels.size()) + " channels " + std::to_string(width) +
                             " pixels wide take " + std::to_string(band_bytes(band) >> 20) + " MiB a band of " +
                             std::to_string(std::min(height, band + 2 * kHalo)) + " rows, over the " +
                             std::to_string(kMaxBandBytes >> 20) + " MiB the denoiser holds");
  const RemoveOnInterrupt interrupted{tmp};
  // OpenEXR's errors on the output name the output file; those reading or denoising the
  // input name it already (below).
  auto writing = [&](auto&& step) {
    try {
      step();
    } catch (const std::exception& e) {
      throw std::runtime_error(out_path + ": cannot write EXR: " + e.what());
    }
  };
  try {
    std::unique_ptr<Imf::OutputFile> file;
    writing([&] { file = std::make_unique<Imf::OutputFile>(tmp.c_str(), header); });
    for (int b0 = 0; b0 < height; b0 += band) {
      const int b1 = std::min(height, b0 + band), r0 = std::max(0, b0 - kHalo), r1 = std::min(height, b1 + kHalo);
      // Rows r0..r1 of every channel: the band and its halo.
      Planes planes;
      Imf::FrameBuffer in_fb;
      for (const std::string& c : channels) {
        std::vector<float>& plane = planes[c];
        plane.resize(size_t(width) * size_t(r1 - r0));
        in_fb.insert(c, slice(plane, width, r0, dw.min.x, dw.min.y, types[c]));
      }
      try {
        input->setFrameBuffer(in_fb);
        input->readPixels(dw.min.y + r0, dw.min.y + r1 - 1);
      } catch (const std::exception& e) {
        throw std::runtime_error(in_path + ": cannot read EXR: " + e.what());
      }
      const auto t0 = std::chrono::steady_clock::now();
      std::vector<float> rgb;
      try {
        // (Its messages name pixels as the image has them: the data window's origin added.)
        rgb = denoise(buffers_of(planes, width, r1 - r0, dw.min.y + r0, dw.min.x, again), options);
      } catch (const std::invalid_argument& e) {
        throw std::runtime_error(in_path + ": cannot denoise: " + e.what());
      }
      report.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      // The band's rows out: the noisy image to noisy.* (unless there), the denoised to R, G, B.
      const size_t skip = size_t(b0 - r0) * size_t(width), n = size_t(b1 - b0) * size_t(width);
      for (int c = 0; c < 3; ++c) {
        std::vector<float>& plane = planes[std::string(1, "RGB"[c])];
        if (!again) planes[kNoisyChannels[c]] = plane;
        for (size_t i = 0; i < n; ++i) plane[skip + i] = rgb[3 * (skip + i) + size_t(c)];
      }
      Imf::FrameBuffer out_fb;
      for (const std::string& c : out_channels)
        out_fb.insert(c, slice(planes[c], width, r0, dw.min.x, dw.min.y, types.count(c) ? types[c] : Imf::FLOAT));
      writing([&] {
        file->setFrameBuffer(out_fb);
        file->writePixels(b1 - b0);
      });
    }
  } catch (...) {
    std::remove(tmp.c_str());
    throw;
  }
  commit_file(tmp, out_path);
  return report;
}

}  // namespace tessera
