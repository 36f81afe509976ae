// The half-buffers (issue 26, for the denoiser): a film's second plane of sums holds each
// pixel's odd-numbered samples, added in pass order like the first, so it is the same bits
// whatever the threads, tiles and runs of passes; the image itself does not change.
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <gtest/gtest.h>

#include <filesystem>

#include "core/io/image_io.h"
#include "core/render/frame_plan.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

bool same(const PixelSums& a, const PixelSums& b) {
  return a.r == b.r && a.g == b.g && a.b == b.b && a.lum2 == b.lum2 && a.n == b.n;
}

class Halves : public ::testing::Test {
 protected:
  // A diffuse sphere lit by a white environment: noisy at a few samples.
  const Scene scene = [] {
    Material m;
    m.reflectance = Rgb(0.7f, 0.5f, 0.3f);
    return testing::lone_sphere(m);
  }();
  static RenderSettings settings(uint32_t aovs) {
    RenderSettings s;
    s.camera.width = 24;
    s.camera.height = 24;
    s.spp = 24;
    s.pass_spp = 8;
    s.max_depth = 3;
    s.environment = Rgb(1.0f);  // the light
    s.aovs = aovs;
    return s;
  }
  fs::path dir = fs::temp_directory_path() / ("tessera_halves_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(Halves, TheOddPlaneHoldsTheOddSamplesInPassOrderAndTheImageIsUnchanged) {
  const RenderResult with = testing::render(scene, settings(kAovDenoising));
  const RenderResult without = testing::render(scene, settings(0));
  ASSERT_TRUE(with.film.halves());
  EXPECT_FALSE(without.film.halves());
  for (size_t i = 0; i < with.film.pixels().size(); ++i) {
    ASSERT_TRUE(same(with.film.pixels()[i], without.film.pixels()[i])) << "pixel " << i;
    EXPECT_EQ(with.film.odd()[i].n, 12u);
  }
  // One pixel by hand: each pass's odd samples summed in sample order, the passes added in
  // pass order, as the film adds them.
  const RenderSettings s = settings(kAovDenoising);
  const TileRenderer tr(scene, s);
  const Rect px{11, 13, 1, 1};
  PixelSums expected;
  for (const auto& [s0, s1] : s.passes()) {
    PixelSums pass;
    for (uint32_t k = s0; k < s1; ++k) {
      const std::vector<PixelSums> one = tr.render(px, k, k + 1, nullptr, nullptr);
      ASSERT_EQ(one.size(), 2u);  // two planes
      EXPECT_TRUE(same(one[1], k % 2 ? one[0] : PixelSums{})) << "sample " << k;
      if (k % 2) {
        pass.r += one[0].r;
        pass.g += one[0].g;
        pass.b += one[0].b;
        pass.lum2 += one[0].lum2;
        pass.n += one[0].n;
      }
    }
    expected.add(pass);
  }
  EXPECT_TRUE(same(with.film.odd_at(11, 13), expected));
}

TEST_F(Halves, TheSameBitsWhateverTheThreadsTilesAndRunsOfPasses) {
  RenderSettings s = settings(kAovDenoising);
  const RenderResult a = testing::render(scene, s, 1, 8);
  const RenderResult b = testing::render(scene, s, 2, 5);
  for (size_t i = 0; i < a.film.odd().size(); ++i) ASSERT_TRUE(same(a.film.odd()[i], b.film.odd()[i])) << i;
  // A run of passes from a base (a worker on a slow link): both planes as the film's.
  const TileRenderer tr(scene, s);
  const Rect rect{4, 4, 6, 5};
  const std::vector<PixelSums> first = tr.render(rect, 0, 8, nullptr, nullptr);
  const std::vector<PixelSums> run = tr.render_passes(rect, {{8, 16}, {16, 24}}, first.data(), nullptr, nullptr);
  ASSERT_EQ(run.size(), size_t(2 * rect.area()));
  for (int y = 0; y < rect.h; ++y)
    for (int x = 0; x < rect.w; ++x) {
      const size_t k = size_t(y) * rect.w + x;
      ASSERT_TRUE(same(run[k], a.film.at(rect.x + x, rect.y + y))) << k;
      ASSERT_TRUE(same(run[size_t(rect.area()) + k], a.film.odd_at(rect.x + x, rect.y + y))) << k;
    }
}

TEST_F(Halves, ThePlanTakesBothPlanesAndRefusesAnOddPlaneWithMoreSamples) {
  RenderSettings s = settings(kAovDenoising);
  FramePlan plan(s);
  const TileTask t = *plan.take();
  const TileRenderer tr(scene, s);
  std::vector<PixelSums> sums = tr.render(t.rect, t.sample_begin, t.sample_end, nullptr, nullptr);
  const size_t area = size_t(t.rect.area());
  EXPECT_EQ(plan.merge(t.tile, t.pass, std::vector<PixelSums>(sums.begin(), sums.begin() + ptrdiff_t(area))),
            FramePlan::Merge::kInvalid);  // one plane where two are due
  std::vector<PixelSums> lying = sums;
  lying[area] = lying[0];
  lying[area].n += 1;  // more odd samples than the pixel has
  lying[area].r += 1;
  EXPECT_EQ(plan.merge(t.tile, t.pass, lying), FramePlan::Merge::kInvalid);
  uint64_t merged = 0;
  EXPECT_EQ(plan.merge(t.tile, t.pass, sums, &merged), FramePlan::Merge::kMerged);
  EXPECT_EQ(merged, area * 8);  // the samples are the first plane's
  EXPECT_TRUE(same(plan.film().odd_at(t.rect.x, t.rect.y), sums[area]));
  // A run's base carries both planes; a reset tile forgets both.
  const TileTask run = *plan.take(2);
  (void)run;
  BandCopy band;
  plan.copy_band(0, &band);
  EXPECT_EQ(band.odd.size(), band.pixels.size());
  plan.reset_tile(t.tile);
  EXPECT_TRUE(same(plan.film().odd_at(t.rect.x, t.rect.y), PixelSums{}));
}

TEST_F(Halves, TheExrCarriesBothHalvesWhoseMeansMakeTheImage) {
  const RenderResult r = testing::render(scene, settings(kAovDenoising));
  const std::string path = (dir / "halves.exr").string();
  write_exr(path, r.film, {}, false, &r.aovs, kAovDenoising);
  const ExrImage img = read_exr(path);
  for (const char* ch : kHalfChannels) ASSERT_TRUE(img.channels.count(ch)) << ch;
  for (size_t i = 0; i < img.channels.at("R").size(); ++i) {
    const float even = img.channels.at("even.G")[i], odd = img.channels.at("odd.G")[i];
    EXPECT_NEAR((even + odd) / 2, img.channels.at("G")[i], 1e-5f * (1 + img.channels.at("G")[i])) << i;
  }
  EXPECT_NE(img.channels.at("even.R"), img.channels.at("odd.R"));  // independent halves
}

TEST(HalvesSettings, DenoisingNamesItsLayersAndDenoiseNeedsThem) {
  EXPECT_EQ(parse_aovs("denoising"), kAovDenoising);
  EXPECT_EQ(parse_aovs("halves"), uint32_t(kAovHalves));
  EXPECT_EQ(parse_aovs("all") & kAovHalves, 0u);  // "all": the compositing passes
  EXPECT_EQ(aov_names(kAovDenoising), "albedo,normal,depth,halves");
  RenderSettings s;
  s.denoise = true;
  s.aovs = kAovAlbedo;
  try {
    s.validate();
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_EQ(e.flag(), "--denoise");
    EXPECT_NE(std::string(e.what()).find("--aov denoising"), std::string::npos) << e.what();
  }
  s.aovs = kAovDenoising | kAovAlpha;
  EXPECT_NO_THROW(s.validate());
  EXPECT_EQ(s.sum_planes(), 2u);
}

}  // namespace
}  // namespace tessera
