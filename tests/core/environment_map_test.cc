// Image environments (--env): reading .hdr and .exr maps and refusing broken ones, CS184's
// lat-long directions and rotation, importance sampling against its density, and renders
// where every estimator agrees.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "core/light/environment.h"
#include "core/light/lights.h"
#include "core/render/tile_renderer.h"
#include "core/sampling/sampler.h"
#include "tests/core/chi2.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::film_estimate;
using testing::render;

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("tessera_env_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

// Radiance RGBE, flat scanlines (what stb reads without run-length encoding).
void write_hdr(const fs::path& path, int w, int h, const std::vector<Rgb>& px) {
  std::ofstream out(path, std::ios::binary);
  out << "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y " << h << " +X " << w << "\n";
  for (const Rgb& c : px) {
    const float m = std::max(c.r, std::max(c.g, c.b));
    if (m < 1e-32f) {
      out.write("\0\0\0\0", 4);
      continue;
    }
    int e;
    const float f = std::frexp(m, &e) * 256.0f / m;
    const char b[4] = {char(int(c.r * f)), char(int(c.g * f)), char(int(c.b * f)), char(e + 128)};
    out.write(b, 4);
  }
}

void write_exr(const fs::path& path, int w, int h, const std::vector<Rgb>& px) {
  std::vector<float> r(px.size()), g(px.size()), b(px.size());
  for (size_t i = 0; i < px.size(); ++i) {
    r[i] = px[i].r;
    g[i] = px[i].g;
    b[i] = px[i].b;
  }
  Imf::Header header(w, h);
  Imf::FrameBuffer fb;
  for (auto& [name, data] : {std::pair<const char*, std::vector<float>*>{"R", &r}, {"G", &g}, {"B", &b}}) {
    header.channels().insert(name, Imf::Channel(Imf::FLOAT));
    fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(data->data()), sizeof(float), sizeof(float) * w));
  }
  Imf::OutputFile file(path.c_str(), header);
  file.setFrameBuffer(fb);
  file.writePixels(h);
}

// The direction of pixel (x, y)'s centre in a W x H map (format doc 7.6, inverted).
Vec3 pixel_direction(int x, int y, int w, int h) {
  const double theta = M_PI * (y + 0.5) / h, phi = 2 * M_PI * (x + 0.5) / w - M_PI;
  return {float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)), float(-std::sin(theta) * std::sin(phi))};
}

RgbImage one_bright_pixel(int w, int h, int x, int y, Rgb c) {
  RgbImage img;
  img.width = w;
  img.height = h;
  img.texels.assign(size_t(w) * h, Rgb(0.0f));
  img.texels[size_t(y) * w + x] = c;
  return img;
}

// What read_environment_image says of the file, or "no error".
std::string error_of(const fs::path& p) {
  try {
    (void)read_environment_image(p.string());
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "no error";
}

TEST(EnvironmentImage, ReadsHdrAndExrAlike) {
  const fs::path d = temp_dir();
  std::vector<Rgb> px = {Rgb(1, 2, 3), Rgb(0.5f, 0.25f, 0.125f), Rgb(0.0f), Rgb(100, 50, 25)};
  write_hdr(d / "a.hdr", 2, 2, px);
  write_exr(d / "a.exr", 2, 2, px);
  const RgbImage h = read_environment_image((d / "a.hdr").string()), e = read_environment_image((d / "a.exr").string());
  ASSERT_EQ(h.width, 2);
  ASSERT_EQ(e.height, 2);
  for (size_t i = 0; i < px.size(); ++i) {
    EXPECT_FLOAT_EQ(e.texels[i].g, px[i].g);
    EXPECT_NEAR(h.texels[i].g, px[i].g, 0.01 * px[i].g);  // RGBE keeps 8 bits of mantissa
  }
  EXPECT_FLOAT_EQ(e.texels[3].r, 100);  // red by channel name, not CS184's alphabetical-order quirk
}

TEST(EnvironmentImage, RefusesWhatIsNotARadianceMapNamingTheProblem) {
  const fs::path d = temp_dir();
  EXPECT_NE(error_of(d / "missing.hdr").find("missing.hdr: no such file"), std::string::npos);
  std::ofstream(d / "sky.png") << "not an image";
  EXPECT_NE(error_of(d / "sky.png").find("must be .exr or .hdr"), std::string::npos);
  std::ofstream(d / "junk.hdr") << "junk";
  EXPECT_NE(error_of(d / "junk.hdr").find("not a Radiance HDR image"), std::string::npos);
  std::ofstream(d / "junk.exr") << "junk";
  EXPECT_NE(error_of(d / "junk.exr").find("cannot read EXR"), std::string::npos);
  // A header that claims 10^10 pixels is refused before anything is allocated.
  std::ofstream(d / "huge.hdr") << "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n";
  EXPECT_NE(error_of(d / "huge.hdr").find("beyond the limit"), std::string::npos) << error_of(d / "huge.hdr");
  write_exr(d / "nan.exr", 2, 1, {Rgb(1.0f), Rgb(NAN, 0, 0)});
  EXPECT_NE(error_of(d / "nan.exr").find("pixel (1, 0) is negative, NaN or infinite"), std::string::npos);
  write_exr(d / "neg.exr", 1, 1, {Rgb(-1, 0, 0)});
  EXPECT_NE(error_of(d / "neg.exr").find("pixel (0, 0)"), std::string::npos);
}

// Found by audit: a Radiance file cut short was decoded with its missing pixels as zeros
// (part of the sky black, nothing said); read_exr allocated every channel a header named
// (40 channels of 2^26 pixels: 10 GB from a 1 KB file).
TEST(EnvironmentImage, ACutShortHdrAndAnExrTooLargeToReadAreRefused) {
  const fs::path d = temp_dir();
  std::vector<Rgb> px(64, Rgb(1, 2, 3));
  write_hdr(d / "whole.hdr", 8, 8, px);
  EXPECT_EQ(error_of(d / "whole.hdr"), "no error");
  std::string bytes;
  {
    std::ifstream in(d / "whole.hdr", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::ofstream(d / "cut.hdr", std::ios::binary) << bytes.substr(0, bytes.size() - 40);
  EXPECT_NE(error_of(d / "cut.hdr").find("cut.hdr: the HDR image is cut short (the file ends before its 8 x 8"),
            std::string::npos)
      << error_of(d / "cut.hdr");
  std::ofstream(d / "bare.hdr") << "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 64 +X 64\n";  // no pixels at all
  EXPECT_NE(error_of(d / "bare.hdr").find("cut short"), std::string::npos) << error_of(d / "bare.hdr");
  {  // a header of 40 channels of 8192 x 8192 pixels, no pixels written
    Imf::Header header(8192, 8192);
    for (int c = 0; c < 40; ++c) header.channels().insert("c" + std::to_string(c), Imf::Channel(Imf::FLOAT));
    Imf::OutputFile file((d / "wide.exr").c_str(), header);
  }
  try {
    (void)read_exr((d / "wide.exr").string());
    ADD_FAILURE() << "read";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("40 channels of 8192 x 8192 pixels would take 10240 MiB, over the 4096 MiB"),
              std::string::npos)
        << e.what();
  }
  {  // R and G, no B
    float v[2] = {1, 2};
    Imf::Header header(2, 1);
    Imf::FrameBuffer fb;
    for (const char* c : {"R", "G"}) {
      header.channels().insert(c, Imf::Channel(Imf::FLOAT));
      fb.insert(c, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(v), sizeof(float), 2 * sizeof(float)));
    }
    Imf::OutputFile file((d / "rg.exr").c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(1);
  }
  EXPECT_NE(error_of(d / "rg.exr").find("only some of the channels R, G and B"), std::string::npos)
      << error_of(d / "rg.exr");
  // Only the channels asked for are read.
  write_exr(d / "rgb.exr", 2, 1, {Rgb(1, 2, 3), Rgb(4, 5, 6)});
  const ExrImage only_g = read_exr((d / "rgb.exr").string(), {"G"});
  ASSERT_EQ(only_g.channels.size(), 1u);
  EXPECT_EQ(only_g.channels.at("G")[1], 5);
}

TEST(EnvironmentMap, LooksUpCs184DirectionsAndTurnsAboutY) {
  const int w = 16, h = 8;
  const EnvironmentMap map(one_bright_pixel(w, h, 5, 2, Rgb(3.0f)), 0);
  EXPECT_NEAR(map.radiance(pixel_direction(5, 2, w, h)).g, 3, 1e-5);  // a pixel centre: bilinear is exact
  EXPECT_FLOAT_EQ(map.radiance(pixel_direction(6, 2, w, h)).g, 0);
  EXPECT_FLOAT_EQ(map.radiance({0, 1, 0}).g, 0);  // row 0 is +Y
  // Turned 90 degrees about +Y: the pixel is seen where its direction has turned to.
  const EnvironmentMap turned(one_bright_pixel(w, h, 5, 2, Rgb(3.0f)), 90);
  const Vec3 d = pixel_direction(5, 2, w, h);
  const Vec3 r{d.z, d.y, -d.x};  // (cos x + sin z, y, -sin x + cos z) at 90 degrees
  EXPECT_NEAR(turned.radiance(r).g, 3, 1e-4);
  EXPECT_NEAR(turned.radiance(d).g, 0, 1e-4);
  // A black map emits nothing and cannot be sampled.
  const EnvironmentMap black(one_bright_pixel(w, h, 0, 0, Rgb(0.0f)), 0);
  Vec3 wi;
  float pdf;
  EXPECT_FALSE(black.sample({0.5f, 0.5f}, &wi, &pdf));
}

TEST(EnvironmentMap, SamplingFollowsLuminanceAndMatchesItsPdf) {
  // A gradient sky with a bright patch, turned 37 degrees: chi-square of the sampled
  // directions against pdf(), and every sample's pdf equal to pdf() of its direction.
  RgbImage img;
  img.width = 32;
  img.height = 16;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      img.texels.push_back((x >= 20 && x < 23 && y >= 4 && y < 6) ? Rgb(40, 30, 20) : Rgb(0.2f + 0.05f * y));
  const EnvironmentMap map(img, 37);
  const auto r = testing::chi2_directions(
      [&](int i) -> std::optional<Vec3> {
        Sampler s(21, 0, uint32_t(i));
        Vec3 w;
        float pdf;
        if (!map.sample(s.next_2d(), &w, &pdf)) return std::nullopt;
        EXPECT_NEAR(pdf, map.pdf(w), 1e-3f * pdf);
        return w;
      },
      [&](Vec3 w) { return double(map.pdf(w)); }, 400000, 40, 80, 16);
  EXPECT_GT(r.p_value, 1e-3) << r.describe();
  // The density integrates to 1 over the sphere.
  double total = 0;
  const int nz = 800, np = 1600;
  for (int i = 0; i < nz; ++i)
    for (int j = 0; j < np; ++j) {
      const double z = -1 + (i + 0.5) * 2 / nz, phi = (j + 0.5) * 2 * M_PI / np, s = std::sqrt(1 - z * z);
      total +=
          map.pdf(Vec3{float(s * std::cos(phi)), float(z), float(s * std::sin(phi))}) * (2.0 / nz) * (2 * M_PI / np);
    }
  EXPECT_NEAR(total, 1.0, 2e-3);
}

Scene sphere_scene(Material m) {
  Scene s = testing::lone_sphere(std::move(m));
  s.source = (temp_dir() / "scene.gltf").string();  // relative --env paths resolve beside it
  return s;
}

TEST(EnvironmentMapRender, AConstantMapIsTheUniformEnvironment) {
  const fs::path d = temp_dir();
  write_exr(d / "half.exr", 8, 4, std::vector<Rgb>(32, Rgb(0.5f)));
  Material white;
  white.reflectance = Rgb(1.0f);
  RenderSettings s = testing::furnace_settings();
  s.environment_map = "half.exr";  // relative: beside the scene file
  s.environment_strength = 2;
  const testing::Estimate e = film_estimate(render(sphere_scene(white), s).film);
  EXPECT_NEAR(e.mean, 1.0, 4 * e.stderr_ + 2e-3);
}

TEST(EnvironmentMapRender, LightSamplingBsdfSamplingAndMisAgreeUnderABrightPatch) {
  const fs::path d = temp_dir();
  std::vector<Rgb> px(64 * 32, Rgb(0.1f));
  for (int y = 8; y < 12; ++y)
    for (int x = 40; x < 46; ++x) px[size_t(y) * 64 + x] = Rgb(30, 25, 20);
  write_hdr(d / "patch.hdr", 64, 32, px);
  Material grey;
  grey.reflectance = Rgb(0.6f);
  const Scene scene = sphere_scene(grey);
  RenderSettings s = testing::furnace_settings();
  s.environment_map = (d / "patch.hdr").string();  // absolute works too
  s.environment_rotation = 200;
  s.spp = 256;
  std::vector<testing::Estimate> e;
  for (const auto& [nee, mis] : {std::pair{true, true}, {true, false}, {false, true}}) {
    s.nee = nee;
    s.mis = mis;
    e.push_back(film_estimate(render(scene, s).film));
  }
  for (size_t i = 1; i < e.size(); ++i)
    EXPECT_NEAR(e[i].mean, e[0].mean, 4 * std::sqrt(e[i].stderr_ * e[i].stderr_ + e[0].stderr_ * e[0].stderr_))
        << "estimator " << i;
  EXPECT_LT(e[0].stderr_, e[2].stderr_);  // importance sampling the patch beats BSDF sampling alone
}

TEST(EnvironmentMapRender, AMissingMapIsASettingsErrorNamingTheFile) {
  Material white;
  RenderSettings s = testing::furnace_settings();
  s.environment_map = "no-such-sky.hdr";
  try {
    TileRenderer r(sphere_scene(white), s);
    ADD_FAILURE() << "rendered without the map";
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--env");
    EXPECT_NE(std::string(e.what()).find("no-such-sky.hdr: no such file"), std::string::npos) << e.what();
  }
}

// Found by audit: texels were only finite, so one of 1.6e38 (or a bright one times
// --env-strength) made 45% of the samples NaN. Its radiance is bounded as emission is.
TEST(EnvironmentMapRender, AMapBrighterThanEmissionMayBeIsRefusedNamingIt) {
  const fs::path d = temp_dir();
  write_exr(d / "hot.exr", 2, 1, {Rgb(1.0f), Rgb(1.6e38f, 0, 0)});
  write_exr(d / "warm.exr", 2, 1, {Rgb(1.0f), Rgb(1e15f, 0, 0)});
  Material white;
  RenderSettings s = testing::furnace_settings();
  s.environment_map = (d / "hot.exr").string();
  const Scene scene = sphere_scene(white);
  try {
    TileRenderer::check_settings(scene, s);
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--env");
    EXPECT_NE(std::string(e.what()).find("hot.exr: its brightest texel"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("past 1e20"), std::string::npos) << e.what();
  }
  s.environment_map = (d / "warm.exr").string();
  EXPECT_NO_THROW(TileRenderer::check_settings(scene, s));
  s.environment_strength = 1e6f;
  EXPECT_THROW(TileRenderer::check_settings(scene, s), SettingsError);
}

}  // namespace
}  // namespace tessera
