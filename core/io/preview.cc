#include "core/io/preview.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/io/png_encoder.h"

namespace tessera {

namespace {

// A data window no image of ours has (RenderSettings' limits: 65536 a side, 2^27 pixels):
// refused before anything is sized by it (a flipped bit in a header's width, 16 ->
// 4194319, made the coordinator allocate a gigabyte to check the file, then serve it).
void check_window(const Imath::Box2i& dw) {
  const int64_t w = int64_t(dw.max.x) - dw.min.x + 1, h = int64_t(dw.max.y) - dw.min.y + 1;
  if (w < 1 || h < 1 || w > 65536 || h > 65536 || w * h > (int64_t(1) << 27))
    throw std::runtime_error("its data window, " + std::to_string(w) + " x " + std::to_string(h) +
                             ", is no image Tessera writes (a damaged header?)");
}

// The exposure the EXR's render asked for, if any, as PNGs take it.
float file_exposure(const Imf::InputFile& in) {
  ImageMetadata meta;
  if (const auto* a = in.header().findTypedAttribute<Imf::StringAttribute>(kExposureFileAttribute))
    meta[kExposureAttribute] = a->value();
  return exposure_scale(meta);
}

// Reads rows y0 .. y0 + rows - 1 of R, G, B into planes of `w` a row.
void read_rows(Imf::InputFile& in, const Imath::Box2i& dw, int y0, int rows, std::vector<float>* r,
               std::vector<float>* g, std::vector<float>* b) {
  const int w = dw.max.x - dw.min.x + 1;
  Imf::FrameBuffer fb;
  const Imath::V2i origin(dw.min.x, y0);
  for (auto [name, data] : {std::pair{"R", r}, std::pair{"G", g}, std::pair{"B", b}})
    fb.insert(name,
              Imf::Slice::Make(Imf::FLOAT, data->data(), origin, w, rows, sizeof(float), sizeof(float) * size_t(w)));
  in.setFrameBuffer(fb);
  in.readPixels(y0, y0 + rows - 1);
}

// max_width 0: full size, at encode_png's slower, smaller compression (not the preview's),
// read and encoded a band of rows at a time: an 8K image costs a band and the file.
// With a `sink`, the full-size PNG's bytes go there as they are made (and none are returned).
std::string png_of(const std::string& exr_path, int max_width, const PngEncoder::Sink& sink = {}) {
  try {
    Imf::InputFile in(exr_path.c_str());
    const Imath::Box2i dw = in.header().dataWindow();
    check_window(dw);
    const int w = dw.max.x - dw.min.x + 1, h = dw.max.y - dw.min.y + 1;
    const int k = max_width <= 0 ? 1 : std::max(1, (w + max_width - 1) / max_width);  // the box's side
    if (k == 1) {
      constexpr int kBand = 64;
      PngEncoder png(w, h, max_width > 0, sink);
      const float scale = file_exposure(in);
      std::vector<float> r(size_t(w) * size_t(std::min(kBand, h))), g(r.size()), b(r.size());
      for (int y0 = dw.min.y; y0 <= dw.max.y; y0 += kBand) {
        const int rows = std::min(kBand, dw.max.y + 1 - y0);
        read_rows(in, dw, y0, rows, &r, &g, &b);
        for (size_t y = 0; y < size_t(rows); ++y) png.write_row(&r[y * w], &g[y * w], &b[y * w], scale);
      }
      return png.finish();
    }
    const int pw = (w + k - 1) / k, ph = (h + k - 1) / k;
    std::vector<float> pr(size_t(pw) * ph), pg(pr.size()), pb(pr.size());
    std::vector<float> r(size_t(w) * k), g(r.size()), b(r.size());
    for (int py = 0; py < ph; ++py) {
      const int y0 = dw.min.y + py * k, rows = std::min(k, dw.max.y + 1 - y0);
      read_rows(in, dw, y0, rows, &r, &g, &b);
      for (int px = 0; px < pw; ++px) {
        const int x0 = px * k, cols = std::min(k, w - x0);
        double sr = 0, sg = 0, sb = 0;
        for (int y = 0; y < rows; ++y)
          for (int x = x0; x < x0 + cols; ++x) {
            const size_t i = size_t(y) * size_t(w) + size_t(x);
            sr += r[i];
            sg += g[i];
            sb += b[i];
          }
        const double n = double(rows) * double(cols);
        const size_t o = size_t(py) * size_t(pw) + size_t(px);
        pr[o] = float(sr / n);
        pg[o] = float(sg / n);
        pb[o] = float(sb / n);
      }
    }
    return encode_png(pw, ph, pr.data(), pg.data(), pb.data(), true, file_exposure(in));
  } catch (const std::exception& e) {
    throw std::runtime_error(exr_path + (max_width > 0 ? ": cannot make a preview: " : ": cannot make a PNG: ") +
                             e.what());
  }
}

}  // namespace

std::string preview_png(const std::string& exr_path, int max_width) { return png_of(exr_path, std::max(1, max_width)); }

std::string full_png(const std::string& exr_path) { return png_of(exr_path, 0); }

void write_full_png(const std::string& exr_path, const std::string& png_path) {
  AtomicFile out(png_path);
  png_of(exr_path, 0, [&](const char* data, size_t n) { out.append(data, n); });
  out.commit();
}

bool exr_intact(const std::string& exr_path, std::string* why) {
  try {
    Imf::InputFile in(exr_path.c_str());
    const Imath::Box2i dw = in.header().dataWindow();
    const int w = dw.max.x - dw.min.x + 1;
    constexpr int kBand = 64;
    check_window(dw);
    std::vector<float> r(size_t(w) * size_t(std::min(kBand, dw.max.y - dw.min.y + 1)));
    for (int y0 = dw.min.y; y0 <= dw.max.y; y0 += kBand) {
      const int rows = std::min(kBand, dw.max.y + 1 - y0);
      Imf::FrameBuffer fb;  // one channel is enough: a block decodes whole or not at all
      fb.insert("R", Imf::Slice::Make(Imf::FLOAT, r.data(), Imath::V2i(dw.min.x, y0), w, rows, sizeof(float),
                                      sizeof(float) * size_t(w)));
      in.setFrameBuffer(fb);
      in.readPixels(y0, y0 + rows - 1);
    }
    return true;
  } catch (const std::exception& e) {
    if (why) *why = e.what();
    return false;
  }
}

std::map<std::string, std::string> exr_string_attributes(const std::string& exr_path) {
  std::map<std::string, std::string> out;
  try {
    const Imf::InputFile in(exr_path.c_str());
    for (auto it = in.header().begin(); it != in.header().end(); ++it)
      if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute())) out[it.name()] = s->value();
  } catch (const std::exception&) {  // (missing, or not an EXR)
    out.clear();
  }
  return out;
}

}  // namespace tessera
