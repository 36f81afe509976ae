// AOVs (issue 26): values on a scene with known answers, the EXR layers, determinism across
// threads and tilings, and nothing changed (or computed) when they are not asked for.
#include "core/render/aov.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>

#include "core/io/image_io.h"
#include "tests/core/gltf_fixture.h"
#include "tests/core/render_helpers.h"

namespace tessera {
namespace {

// A flat plane z = 0 of base colour (0.5, 0.6, 0.7) covering x + y <= 0 (a triangle 20
// units across), seen head-on by an orthographic camera at z = 3 (depth 3) 1 unit high:
// its silhouette is the image's diagonal from top left to bottom right.
class Aov : public Gltf {
 protected:
  Scene scene() {
    Doc d;
    d.j["nodes"][0]["scale"] = {20, 20, 1};
    d.j["nodes"][0]["translation"] = {-10, -10, 0};
    d.j["nodes"][1]["translation"] = {0, 0, 3};
    d.j["cameras"][0] = {{"type", "orthographic"},
                         {"orthographic", {{"xmag", 0.6667}, {"ymag", 0.5}, {"znear", 0.5}, {"zfar", 100}}}};
    return load(d);
  }
  static RenderSettings settings(uint32_t aovs) {
    RenderSettings s;
    s.camera.framing = Framing::kFile;
    s.camera.width = 32;
    s.camera.height = 24;
    s.spp = 256;
    s.pass_spp = 64;
    s.max_depth = 2;
    s.aovs = aovs;
    return s;
  }
};

TEST_F(Aov, AFlatPlaneHasExactAlbedoNormalAndDepthAndItsSilhouetteIsCoverage) {
  const Scene sc = scene();
  const RenderResult r = testing::render(sc, settings(kAovAll));
  ASSERT_FALSE(r.aovs.empty());
  int covered = 0, empty = 0, edge = 0;
  for (int y = 0; y < 24; ++y)
    for (int x = 0; x < 32; ++x) {
      const AovPixel p = aov_pixel(r.aovs.at(x, y));
      ASSERT_GE(p.alpha, 0);
      ASSERT_LE(p.alpha, 1);
      EXPECT_EQ(r.aovs.at(x, y).n, 256u);
      if (p.alpha == 1) {
        ++covered;
        EXPECT_FLOAT_EQ(p.albedo[0], 0.5f);
        EXPECT_FLOAT_EQ(p.albedo[1], 0.6f);
        EXPECT_FLOAT_EQ(p.albedo[2], 0.7f);
        EXPECT_EQ(p.normal[0], 0);
        EXPECT_EQ(p.normal[1], 0);
        EXPECT_EQ(p.normal[2], 1);
        EXPECT_FLOAT_EQ(p.depth, 3.0f);  // from the camera's plane
        EXPECT_EQ(p.id, 0);
      } else if (p.alpha == 0) {
        ++empty;
        EXPECT_EQ(p.depth, AovPixel::kBackgroundDepth);
        EXPECT_EQ(p.id, -1);
        EXPECT_EQ(p.albedo[0], 0);
        EXPECT_EQ(p.normal[2], 0);
      } else {
        ++edge;
        EXPECT_FLOAT_EQ(p.depth, 3.0f);  // a mean over the samples that hit
      }
    }
  EXPECT_GT(covered, 300);
  EXPECT_GT(empty, 300);
  EXPECT_GE(edge, 24);  // the diagonal crosses every row
  // Bottom left is covered, top right is not; a pixel the diagonal halves is half covered.
  EXPECT_EQ(aov_pixel(r.aovs.at(0, 23)).alpha, 1);
  EXPECT_EQ(aov_pixel(r.aovs.at(31, 0)).alpha, 0);
  EXPECT_NEAR(aov_pixel(r.aovs.at(4, 0)).alpha, 0.5, 0.05);
}

TEST_F(Aov, TheImageIsTheSameBitsWithAndWithoutAovsAndNoneAreKeptUnasked) {
  const Scene sc = scene();
  const RenderResult with = testing::render(sc, settings(kAovAll)), without = testing::render(sc, settings(0));
  EXPECT_TRUE(without.aovs.empty());
  ASSERT_EQ(with.film.pixels().size(), without.film.pixels().size());
  for (size_t i = 0; i < with.film.pixels().size(); ++i) {
    const PixelSums &a = with.film.pixels()[i], &b = without.film.pixels()[i];
    ASSERT_TRUE(a.r == b.r && a.g == b.g && a.b == b.b && a.lum2 == b.lum2 && a.n == b.n) << "pixel " << i;
  }
}

TEST_F(Aov, AovsAreTheSameBitsWhateverTheThreadsTilesAndPasses) {
  const Scene sc = scene();
  RenderSettings s = settings(kAovAll);
  const RenderResult a = testing::render(sc, s, 1, 8);
  s.pass_spp = 16;
  const RenderResult b = testing::render(sc, s, 2, 16);
  for (size_t i = 0; i < a.aovs.pixels().size(); ++i) ASSERT_TRUE(a.aovs.pixels()[i] == b.aovs.pixels()[i]) << i;
  // A run of passes (a farm worker on a slow link) adds up to the passes one by one.
  const TileRenderer tr(sc, s);
  const Rect rect{0, 0, 8, 8};
  std::vector<AovSums> run, one, two;
  tr.render_passes(rect, {{0, 16}, {16, 40}}, nullptr, nullptr, nullptr, nullptr, &run);
  tr.render(rect, 0, 16, nullptr, nullptr, nullptr, &one);
  tr.render(rect, 16, 40, nullptr, nullptr, nullptr, &two);
  for (size_t i = 0; i < run.size(); ++i) {
    AovSums sum = two[i];
    sum.add(one[i]);  // the other order
    ASSERT_TRUE(run[i] == sum) << i;
  }
}

TEST_F(Aov, TheExrCarriesTheLayersUnderTheNamesCompositorsRead) {
  const Scene sc = scene();
  const RenderResult r = testing::render(sc, settings(kAovAlpha | kAovNormal | kAovDepth));
  const std::string path = (dir / "aov.exr").string();
  write_exr(path, r.film, {}, false, &r.aovs, kAovAlpha | kAovNormal | kAovDepth);
  Imf::InputFile in(path.c_str());
  std::vector<std::string> names;
  for (auto it = in.header().channels().begin(); it != in.header().channels().end(); ++it) names.push_back(it.name());
  EXPECT_EQ(names, (std::vector<std::string>{"A", "B", "G", "R", "depth.Z", "normal.X", "normal.Y", "normal.Z", "spp",
                                             "variance"}));
  const ExrImage img = read_exr(path);
  EXPECT_EQ(img.channels.at("A")[23 * 32], 1.0f);    // bottom left: covered
  EXPECT_EQ(img.channels.at("depth.Z")[31], 1e10f);  // top right: background
  EXPECT_EQ(img.channels.at("normal.Z")[23 * 32], 1.0f);
}

TEST(AovNames, AListIsReadAndUnknownNamesAreRefusedNamingThem) {
  EXPECT_EQ(parse_aovs("albedo, normal"), uint32_t(kAovAlbedo | kAovNormal));
  EXPECT_EQ(parse_aovs("all"), kAovAll);
  EXPECT_EQ(parse_aovs(""), 0u);
  EXPECT_EQ(aov_names(kAovAll), "alpha,albedo,normal,depth,id");
  try {
    parse_aovs("albedo,zdepth");
    ADD_FAILURE();
  } catch (const SettingsError& e) {
    EXPECT_NE(std::string(e.what()).find("'zdepth' is not an AOV"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera
