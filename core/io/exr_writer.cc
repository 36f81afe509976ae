#include "core/io/exr_writer.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <cstdio>
#include <limits>
#include <stdexcept>

#include "core/io/files.h"

namespace tessera {

namespace {

Imath::Box2i box(const Rect& r) { return Imath::Box2i({r.x, r.y}, {r.x + r.w - 1, r.y + r.h - 1}); }

}  // namespace

ExrWriter::ExrWriter(std::string path, const Rect& window, const Rect& frame, const ImageMetadata& metadata,
                     bool compress, uint32_t aovs)
    : path_(std::move(path)),
      tmp_(temporary_path(path_)),
      window_(window),
      width_(window.w),
      height_(window.h),
      aovs_(aovs),
      aov_names_(aov_channels(aovs)),
      aov_(aov_names_.size()),
      half_(aovs & kAovHalves ? 6 : 0) {
  Imf::Header header(box(frame), box(window));
  header.compression() = compress ? Imf::ZIP_COMPRESSION : Imf::NO_COMPRESSION;
  for (const auto& [key, value] : metadata) header.insert("tessera/" + key, Imf::StringAttribute(value));
  for (const char* name : {"R", "G", "B", "spp", "variance"}) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
  for (const std::string& name : aov_names_) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
  if (!half_.empty())
    for (const char* name : kHalfChannels) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
  try {
    file_ = std::make_unique<Imf::OutputFile>(tmp_.c_str(), header);
  } catch (const std::exception& e) {
    std::remove(tmp_.c_str());
    throw std::runtime_error(path_ + ": cannot write EXR: " + e.what());
  }
}

ExrWriter::~ExrWriter() {
  if (!file_) return;
  try {
    file_.reset();
  } catch (...) {
  }
  std::remove(tmp_.c_str());
}

void ExrWriter::write_rows(const PixelSums* sums, int rows, const AovSums* aov, const PixelSums* odd) {
  if (!file_ || rows <= 0 || next_row_ + rows > height_) throw std::runtime_error(path_ + ": EXR rows out of order");
  if ((aovs_ & kAovAll && !aov) || (!half_.empty() && !odd))
    throw std::runtime_error(path_ + ": EXR rows without the AOVs its header names");
  const size_t n = size_t(rows) * size_t(width_);
  for (std::vector<float>* v : {&r_, &g_, &b_, &spp_, &var_}) v->resize(n);
  for (size_t i = 0; i < n; ++i) {
    const PixelSums& p = sums[i];
    const Rgb m = p.mean();
    r_[i] = m.r;
    g_[i] = m.g;
    b_[i] = m.b;
    spp_[i] = float(p.n);
    // (float's largest where the variance passes it: an emitter near the 1e20 bound squares
    // past float; +inf read as a value, not an overflow)
    var_[i] = float(std::min(p.mean_variance(), double(std::numeric_limits<float>::max())));
  }
  Imf::FrameBuffer fb;
  const Imath::V2i origin(window_.x, window_.y + next_row_);  // these rows' place in the image
  const std::pair<const char*, std::vector<float>*> channels[] = {
      {"R", &r_}, {"G", &g_}, {"B", &b_}, {"spp", &spp_}, {"variance", &var_}};
  for (const auto& [name, data] : channels)
    fb.insert(name, Imf::Slice::Make(Imf::FLOAT, data->data(), origin, width_, rows, sizeof(float),
                                     sizeof(float) * size_t(width_)));
  if (!half_.empty()) {
    for (auto& plane : half_) plane.resize(n);
    for (size_t i = 0; i < n; ++i) {
      float even_rgb[3], odd_rgb[3];
      half_means(sums[i], odd[i], even_rgb, odd_rgb);
      for (int c = 0; c < 3; ++c) {
        half_[c][i] = even_rgb[c];
        half_[3 + c][i] = odd_rgb[c];
      }
    }
    for (size_t c = 0; c < half_.size(); ++c)
      fb.insert(kHalfChannels[c], Imf::Slice::Make(Imf::FLOAT, half_[c].data(), origin, width_, rows, sizeof(float),
                                                   sizeof(float) * size_t(width_)));
  }
  if (aovs_ & kAovAll) {
    for (auto& plane : aov_) plane.resize(n);
    float values[16];  // one pixel's, in aov_channels' order (at most 9)
    for (size_t i = 0; i < n; ++i) {
      aov_channel_values(aov[i], aovs_, values);
      for (size_t c = 0; c < aov_.size(); ++c) aov_[c][i] = values[c];
    }
    for (size_t c = 0; c < aov_.size(); ++c)
      fb.insert(aov_names_[c], Imf::Slice::Make(Imf::FLOAT, aov_[c].data(), origin, width_, rows, sizeof(float),
                                                sizeof(float) * size_t(width_)));
  }
  try {
    file_->setFrameBuffer(fb);
    file_->writePixels(rows);
  } catch (const std::exception& e) {
    throw std::runtime_error(path_ + ": cannot write EXR: " + e.what());
  }
  next_row_ += rows;
}

void ExrWriter::commit() {
  if (next_row_ != height_) throw std::runtime_error(path_ + ": EXR closed with rows missing");
  try {
    file_.reset();  // writes the offset table and closes the file
  } catch (const std::exception& e) {
    std::remove(tmp_.c_str());
    throw std::runtime_error(path_ + ": cannot write EXR: " + e.what());
  }
  commit_file(tmp_, path_);
}

}  // namespace tessera
