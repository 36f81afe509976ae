// tessera denoise on files it did not write itself (found by audit): an input named as the
// output's temporary file is refused and kept (it was truncated, then removed), a file with
// the noisy image but no R, G, B is refused (it crashed), the output keeps the input's
// data and display windows, attributes and integer channels, a file of several parts is
// refused (all but the first were dropped), and a band's memory counts the denoiser's
// padded grid (a 2^20 x 10 image took 5 GB).
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfChromaticitiesAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfMultiPartOutputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfOutputPart.h>
#include <OpenEXR/ImfPartType.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <limits>
#include <map>
#include <random>

#include "core/denoise/denoise_exr.h"
#include "core/io/files.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

const char* const kNeeded[] = {"R",        "G",        "B",        "even.R",   "even.G",   "even.B",
                               "odd.R",    "odd.G",    "odd.B",    "albedo.R", "albedo.G", "albedo.B",
                               "normal.X", "normal.Y", "normal.Z", "depth.Z"};

class DenoiseExrInputs : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_denoise_inputs_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }

  // A noisy grey image with every layer the denoiser reads, in `header`'s data window, the
  // channels named in `skip` left out, and `extra` UINT channels holding `id`.
  std::map<std::string, std::vector<float>> planes;
  std::vector<uint32_t> ids;
  void fill(Imf::Header& header, const std::vector<std::string>& skip = {}, const char* extra = nullptr) {
    const Imath::Box2i dw = header.dataWindow();
    const size_t n = size_t(dw.max.x - dw.min.x + 1) * size_t(dw.max.y - dw.min.y + 1);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.2f, 0.8f);
    for (const char* c : kNeeded) {
      if (std::find(skip.begin(), skip.end(), c) != skip.end()) continue;
      std::vector<float>& p = planes[c];
      p.resize(n);
      for (float& x : p) x = c[0] == 'd' ? 3.f : c[0] == 'n' ? 0.577f : c[0] == 'a' ? 0.5f : u(rng);
      header.channels().insert(c, Imf::Channel(Imf::FLOAT));
    }
    if (extra) {
      ids.assign(n, 16777217u);
      header.channels().insert(extra, Imf::Channel(Imf::UINT));
    }
  }
  Imf::FrameBuffer frame(const Imf::Header& header, const char* extra = nullptr) {
    const Imath::Box2i dw = header.dataWindow();
    const long long w = dw.max.x - dw.min.x + 1, origin = dw.min.x + dw.min.y * w;
    Imf::FrameBuffer fb;
    for (auto& [name, p] : planes)
      fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(p.data() - origin), sizeof(float),
                                 sizeof(float) * size_t(w)));
    if (extra)
      fb.insert(extra, Imf::Slice(Imf::UINT, reinterpret_cast<char*>(ids.data() - origin), sizeof(uint32_t),
                                  sizeof(uint32_t) * size_t(w)));
    return fb;
  }
  void write(const std::string& path, Imf::Header header, const std::vector<std::string>& skip = {},
             const char* extra = nullptr) {
    fill(header, skip, extra);
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(frame(header, extra));
    file.writePixels(header.dataWindow().max.y - header.dataWindow().min.y + 1);
  }
  std::string refusal(const std::string& in, const std::string& out) {
    try {
      denoise_exr(in, out);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "(accepted)";
  }
};

TEST_F(DenoiseExrInputs, AnInputNamedAsTheOutputsTemporaryFileIsRefusedAndKept) {
  const std::string out = (dir / "x.exr").string(), in = out + ".tmp";
  write(in, Imf::Header(16, 12));
  const std::string before = read_file_bytes(in);
  const std::string why = refusal(in, out);
  EXPECT_NE(why.find("the input is the output's temporary file"), std::string::npos) << why;
  EXPECT_EQ(read_file_bytes(in), before);
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(DenoiseExrInputs, TheNoisyImageWithoutRgbIsRefusedNamingThem) {
  const std::string in = (dir / "again.exr").string();
  Imf::Header header(16, 12);
  for (const char* c : {"noisy.R", "noisy.G", "noisy.B"}) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
  write(in, header, {"R", "G", "B"});
  const std::string why = refusal(in, (dir / "out.exr").string());
  EXPECT_NE(why.find("cannot denoise: no R, G, B channel(s)"), std::string::npos) << why;
}

TEST_F(DenoiseExrInputs, TheOutputKeepsTheInputsWindowsAttributesAndIntegerChannels) {
  const std::string in = (dir / "in.exr").string(), out = (dir / "out.exr").string();
  Imf::Header header(Imath::Box2i({0, 0}, {63, 47}), Imath::Box2i({10, 5}, {41, 28}));
  header.insert("chromaticities", Imf::ChromaticitiesAttribute(Imf::Chromaticities()));
  write(in, header, {}, "id.V");
  denoise_exr(in, out);
  Imf::InputFile got(out.c_str());
  EXPECT_EQ(got.header().dataWindow(), Imath::Box2i({10, 5}, {41, 28}));
  EXPECT_EQ(got.header().displayWindow(), Imath::Box2i({0, 0}, {63, 47}));
  EXPECT_NE(got.header().findTypedAttribute<Imf::ChromaticitiesAttribute>("chromaticities"), nullptr);
  ASSERT_NE(got.header().channels().findChannel("id.V"), nullptr);
  EXPECT_EQ(got.header().channels().findChannel("id.V")->type, Imf::UINT);
  EXPECT_NE(got.header().channels().findChannel("noisy.G"), nullptr);
  std::vector<float> noisy_g(planes["G"].size());
  std::vector<uint32_t> id(ids.size());
  Imf::FrameBuffer fb;
  const long long origin = 10 + 5 * 32;
  fb.insert("noisy.G", Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(noisy_g.data() - origin), sizeof(float),
                                  sizeof(float) * 32));
  fb.insert("id.V", Imf::Slice(Imf::UINT, reinterpret_cast<char*>(id.data() - origin), sizeof(uint32_t),
                               sizeof(uint32_t) * 32));
  got.setFrameBuffer(fb);
  got.readPixels(5, 28);
  EXPECT_EQ(noisy_g, planes["G"]);  // the noisy image where it was
  EXPECT_EQ(id, ids);               // 16777217: not rounded through a float
}

// A non-finite value is named at its pixel in the image: the data window's origin added (it
// was named relative to the window).
TEST_F(DenoiseExrInputs, ANonFiniteValueIsNamedAtItsPixelInTheImage) {
  const std::string in = (dir / "nan.exr").string();
  Imf::Header header(Imath::Box2i({0, 0}, {63, 47}), Imath::Box2i({10, 5}, {41, 28}));
  fill(header);
  planes["even.G"][size_t(7 - 5) * 32 + (12 - 10)] = std::numeric_limits<float>::quiet_NaN();
  {
    Imf::OutputFile file(in.c_str(), header);
    file.setFrameBuffer(frame(header));
    file.writePixels(24);
  }
  const std::string why = refusal(in, (dir / "out.exr").string());
  EXPECT_NE(why.find("'even' buffer has a non-finite value (nan) at pixel (12, 7)"), std::string::npos) << why;
}

TEST_F(DenoiseExrInputs, AFileOfSeveralPartsIsRefusedNamingThem) {
  const std::string in = (dir / "multi.exr").string();
  std::vector<Imf::Header> headers(2, Imf::Header(16, 12));
  for (Imf::Header& h : headers) {
    fill(h);
    h.setType(Imf::SCANLINEIMAGE);
  }
  headers[0].setName("base");
  headers[1].setName("other");
  {
    Imf::MultiPartOutputFile file(in.c_str(), headers.data(), 2);
    for (int p = 0; p < 2; ++p) {
      Imf::OutputPart part(file, p);
      part.setFrameBuffer(frame(headers[size_t(p)]));
      part.writePixels(12);
    }
  }
  const std::string why = refusal(in, (dir / "out.exr").string());
  EXPECT_NE(why.find(in + ": cannot read EXR: it has 2 parts"), std::string::npos) << why;
  EXPECT_FALSE(fs::exists(dir / "out.exr"));
}

TEST_F(DenoiseExrInputs, AWideShortImageIsRefusedByWhatTheDenoiserWouldHold) {
  const std::string in = (dir / "wide.exr").string();
  {
    Imf::Header header(1 << 20, 10);
    for (const char* c : kNeeded) header.channels().insert(c, Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file(in.c_str(), header);  // no pixels: the bound comes first
  }
  const std::string why = refusal(in, (dir / "out.exr").string());
  EXPECT_EQ(why.rfind(in + ": 16 channels 1048576 pixels wide take", 0), 0u) << why;
  EXPECT_NE(why.find("over the 1024 MiB the denoiser holds"), std::string::npos) << why;
}

}  // namespace
}  // namespace tessera
