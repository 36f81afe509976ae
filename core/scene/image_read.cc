#include "core/scene/image_read.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <stdexcept>

namespace tessera {

ExrImage read_exr(const std::string& path, const std::set<std::string>& only) {
  ExrImage img;
  try {
    Imf::InputFile file(path.c_str());
    const Imath::Box2i dw = file.header().dataWindow();
    const long long w = (long long)dw.max.x - dw.min.x + 1, h = (long long)dw.max.y - dw.min.y + 1;
    if (w < 1 || h < 1 || w * h > kMaxEnvironmentTexels)
      throw std::runtime_error(std::to_string(w) + " x " + std::to_string(h) + " pixels is beyond the " +
                               std::to_string(kMaxEnvironmentTexels) + "-pixel limit");
    img.width = int(w);
    img.height = int(h);
    img.x0 = dw.min.x;
    img.y0 = dw.min.y;
    uint64_t channels = 0;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
      channels += only.empty() || only.count(it.name());
    if (channels * uint64_t(w) * uint64_t(h) * sizeof(float) > kMaxExrReadBytes)
      throw std::runtime_error(std::to_string(channels) + " channels of " + std::to_string(w) + " x " +
                               std::to_string(h) + " pixels would take " +
                               std::to_string((channels * uint64_t(w) * uint64_t(h) * sizeof(float)) >> 20) +
                               " MiB, over the " + std::to_string(kMaxExrReadBytes >> 20) + " MiB limit");
    Imf::FrameBuffer fb;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it) {
      if (!only.empty() && !only.count(it.name())) continue;
      std::vector<float>& data = img.channels[it.name()];
      data.resize(size_t(img.width) * img.height);
      char* base = reinterpret_cast<char*>(data.data()) -
                   (ptrdiff_t(dw.min.x) + ptrdiff_t(dw.min.y) * img.width) * ptrdiff_t(sizeof(float));
      fb.insert(it.name(), Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * size_t(img.width)));
    }
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    for (auto it = file.header().begin(); it != file.header().end(); ++it)
      if (const auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute()))
        img.metadata[it.name()] = s->value();
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": cannot read EXR: " + e.what());
  }
  return img;
}

RgbImage read_environment_image(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw std::runtime_error(path + ": no such file");
  const std::string ext = std::filesystem::path(path).extension().string();
  RgbImage img;
  if (ext == ".exr" || ext == ".EXR") {
    ExrImage exr = read_exr(path, {"R", "G", "B", "Y"});
    const size_t colours = exr.channels.count("R") + exr.channels.count("G") + exr.channels.count("B");
    const bool rgb = colours == 3;
    if (colours == 1 || colours == 2)  // (read as grey from Y, saying nothing, before)
      throw std::runtime_error(path + ": the EXR has only some of the channels R, G and B");
    if (!rgb && !exr.channels.count("Y")) throw std::runtime_error(path + ": the EXR has no R, G, B (or Y) channels");
    img.width = exr.width;
    img.height = exr.height;
    img.texels.resize(size_t(img.width) * img.height);
    for (size_t i = 0; i < img.texels.size(); ++i)
      img.texels[i] =
          rgb ? Rgb(exr.channels["R"][i], exr.channels["G"][i], exr.channels["B"][i]) : Rgb(exr.channels["Y"][i]);
  } else if (ext == ".hdr" || ext == ".HDR") {
    int w = 0, h = 0, n = 0;
    if (!stbi_info(path.c_str(), &w, &h, &n) || !stbi_is_hdr(path.c_str()))
      throw std::runtime_error(path + ": not a Radiance HDR image");
    if (w < 1 || h < 1 || (long long)w * h > kMaxEnvironmentTexels)
      throw std::runtime_error(path + ": " + std::to_string(w) + " x " + std::to_string(h) +
                               " pixels is beyond the limit");
    // Through callbacks that note a read past the file's end: stb decodes what is not there
    // as zeros (a file cut short rendered part of its sky black, saying nothing).
    struct File {
      std::FILE* f;
      bool past_end = false;
    } file{std::fopen(path.c_str(), "rb")};
    if (!file.f) throw std::runtime_error(path + ": cannot open");
    const std::unique_ptr<std::FILE, int (*)(std::FILE*)> closer(file.f, std::fclose);
    const stbi_io_callbacks io{[](void* u, char* data, int size) {
                                 File& fl = *static_cast<File*>(u);
                                 const size_t got = std::fread(data, 1, size_t(std::max(size, 0)), fl.f);
                                 fl.past_end = fl.past_end || (got == 0 && size > 0);
                                 return int(got);
                               },
                               [](void* u, int n) { std::fseek(static_cast<File*>(u)->f, n, SEEK_CUR); },
                               [](void* u) { return std::feof(static_cast<File*>(u)->f); }};
    std::unique_ptr<float, void (*)(void*)> data(stbi_loadf_from_callbacks(&io, &file, &w, &h, &n, 3), stbi_image_free);
    if (!data) throw std::runtime_error(path + ": cannot read HDR: " + stbi_failure_reason());
    if (file.past_end)
      throw std::runtime_error(path + ": the HDR image is cut short (the file ends before its " + std::to_string(w) +
                               " x " + std::to_string(h) + " pixels do)");
    img.width = w;
    img.height = h;
    img.texels.resize(size_t(w) * h);
    for (size_t i = 0; i < img.texels.size(); ++i)
      img.texels[i] = Rgb(data.get()[3 * i], data.get()[3 * i + 1], data.get()[3 * i + 2]);
  } else {
    throw std::runtime_error(path + ": an environment map must be .exr or .hdr");
  }
  for (size_t i = 0; i < img.texels.size(); ++i) {
    const Rgb& c = img.texels[i];
    if (!(c.r >= 0 && c.g >= 0 && c.b >= 0) || !c.is_finite())
      throw std::runtime_error(path + ": pixel (" + std::to_string(i % size_t(img.width)) + ", " +
                               std::to_string(i / size_t(img.width)) + ") is negative, NaN or infinite");
  }
  return img;
}

}  // namespace tessera
