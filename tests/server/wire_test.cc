// The wire helpers: scene bundles (with a glTF's external files), sums codec, settings.
#include "wire.h"

#include <gtest/gtest.h>
#include <zstd.h>

#include <array>
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "core/scene/load.h"
#include "scene_bundle.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

class Wire : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_wire_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir / "src" / "data"); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(Wire, GltfBundleCarriesItsExternalFilesAndLoadsElsewhere) {
  // dof-row.gltf with its buffer moved out to data/my buffer.bin (percent-encoded URI).
  std::ifstream in(testing::source_path("scenes/dof-row.gltf"));
  nlohmann::json j = nlohmann::json::parse(in);
  const std::string uri = j["buffers"][0]["uri"];
  const std::string b64 = uri.substr(uri.find(',') + 1);
  std::string bin;
  {  // decode base64 with the standard alphabet
    int val = 0, bits = -8;
    for (char c : b64) {
      const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
      const char* p = std::strchr(t, c);
      if (!p || c == '\0') break;
      val = (val << 6) + int(p - t);
      bits += 6;
      if (bits >= 0) {
        bin.push_back(char((val >> bits) & 0xFF));
        bits -= 8;
      }
    }
  }
  ASSERT_EQ(bin.size(), j["buffers"][0]["byteLength"].get<size_t>());
  std::ofstream(dir / "src" / "data" / "my buffer.bin", std::ios::binary) << bin;
  j["buffers"][0]["uri"] = "data/my%20buffer.bin";
  std::ofstream(dir / "src" / "row.gltf") << j.dump();

  v1::SubmitJobRequest req;
  std::string main;
  pack_scene((dir / "src" / "row.gltf").string(), &main, req.mutable_files());
  EXPECT_EQ(main, "row.gltf");
  ASSERT_EQ(req.files_size(), 2);  // the scene and its buffer; the texture is embedded
  EXPECT_EQ(req.files(1).path(), "data/my buffer.bin");
  const std::string hash = bundle_hash(main, req.files());
  EXPECT_EQ(hash.size(), 32u);
  const std::string unpacked = unpack_bundle((dir / "dst").string(), main, req.files());
  EXPECT_EQ(load_scene(unpacked).triangle_count(),
            load_scene(testing::source_path("scenes/dof-row.gltf")).triangle_count());
}

TEST_F(Wire, BundlesRefusePathsOutsideTheirFolder) {
  nlohmann::json j = {{"asset", {{"version", "2.0"}}}, {"buffers", {{{"byteLength", 4}, {"uri", "../escape.bin"}}}}};
  std::ofstream(dir / "src" / "bad.gltf") << j.dump();
  v1::SubmitJobRequest req;
  std::string main;
  EXPECT_THROW(pack_scene((dir / "src" / "bad.gltf").string(), &main, req.mutable_files()), std::runtime_error);
  google::protobuf::RepeatedPtrField<v1::SceneFile> files;
  v1::SceneFile* f = files.Add();
  f->set_path("/etc/passwd");
  EXPECT_THROW(unpack_bundle((dir / "x").string(), "/etc/passwd", files), WireError);
  f->set_path("a/../../b.dae");
  EXPECT_THROW(unpack_bundle((dir / "x").string(), "a/../../b.dae", files), WireError);
}

TEST(WireCodec, SumsRoundTripExactlyAndHostileDataIsRefused) {
  std::vector<PixelSums> sums(37);
  for (size_t i = 0; i < sums.size(); ++i) sums[i] = PixelSums{0.1 * double(i), 1.0 / 3, -0.0, 1e-300, uint32_t(i)};
  const std::string enc = encode_sums(sums);
  const std::vector<PixelSums> dec = decode_sums(enc, sums.size());
  for (size_t i = 0; i < sums.size(); ++i) {
    EXPECT_EQ(std::memcmp(&dec[i].r, &sums[i].r, 8), 0);
    EXPECT_EQ(std::memcmp(&dec[i].g, &sums[i].g, 8), 0);
    EXPECT_EQ(dec[i].n, sums[i].n);
  }
  // Every byte of every field, for sizes around the decoder's groups of eight pixels.
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> value(-1e10, 1e10);
  for (size_t n : {1, 7, 8, 9, 16, 23, 1024, 1031}) {
    std::vector<PixelSums> many(n);
    for (PixelSums& p : many) p = PixelSums{value(rng), value(rng), value(rng), value(rng), uint32_t(rng())};
    const std::vector<PixelSums> back = decode_sums(encode_sums(many), n);
    for (size_t i = 0; i < n; ++i) {
      EXPECT_EQ(std::memcmp(&back[i], &many[i], offsetof(PixelSums, n)), 0) << n << " " << i;
      EXPECT_EQ(back[i].n, many[i].n) << n << " " << i;
    }
  }
  EXPECT_THROW(decode_sums(enc, sums.size() + 1), WireError);  // size mismatch
  EXPECT_THROW(decode_sums("garbage", 1), WireError);
  sums[3].r = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(decode_sums(encode_sums(sums), sums.size()), WireError);
  // Found by fuzz_result (UBSan: pointer arithmetic on an empty vector's null data()).
  EXPECT_TRUE(decode_sums(encode_sums({}), 0).empty());
}

TEST(WireSettings, RoundTripAndRangeChecks) {
  RenderSettings s;
  s.spp = 99;
  s.adaptive = true;
  s.seed = 1234567890123ull;
  s.camera.lens_radius = 0.1f;
  s.window = Rect{2, 3, 4, 5};
  s.tile_size = 24;
  s.noise_target = 0.125;
  s.nee = false;
  s.mis = false;
  EXPECT_FALSE(from_proto(to_proto(s)).frame);  // a still stays a still
  s.frame = -3;
  const RenderSettings r = from_proto(to_proto(s));
  EXPECT_EQ(r.frame, std::optional<int>(-3));
  EXPECT_EQ(r.tile_size, 24);
  EXPECT_EQ(r.noise_target, 0.125);
  EXPECT_FALSE(r.nee);
  EXPECT_FALSE(r.mis);
  // A message without the switches means the defaults: both techniques on.
  EXPECT_TRUE(from_proto(v1::RenderSettings(to_proto(RenderSettings()))).nee);
  EXPECT_EQ(r.spp, 99);
  EXPECT_TRUE(r.adaptive);
  EXPECT_EQ(r.seed, s.seed);
  EXPECT_FLOAT_EQ(r.camera.lens_radius, 0.1f);
  EXPECT_EQ(r.window.h, 5);
  v1::RenderSettings p = to_proto(s);
  p.set_width(0);
  EXPECT_THROW(from_proto(p), WireError);
  p = to_proto(s);
  p.set_lens_radius(-1);
  EXPECT_THROW(from_proto(p), WireError);
  p = to_proto(s);
  p.mutable_window()->set_x(100000);
  EXPECT_THROW(from_proto(p), WireError);
  p = to_proto(s);
  p.set_spp(0xffffffffu);  // past INT_MAX: must not wrap to a small number
  EXPECT_THROW(from_proto(p), WireError);
  p = to_proto(s);
  p.set_noise_target(std::numeric_limits<double>::quiet_NaN());
  try {
    from_proto(p);
    ADD_FAILURE();
  } catch (const WireError& e) {
    EXPECT_NE(std::string(e.what()).find("--noise-target"), std::string::npos) << e.what();
  }
}

// Issue 26: --denoise and the half-buffers travel; a run's base has both planes of sums.
TEST(WireSettings, DenoiseAndHalvesRoundTripAndARunsBaseHasBothPlanes) {
  RenderSettings s;
  s.denoise = true;
  s.aovs = kAovDenoising;
  const RenderSettings r = from_proto(to_proto(s));
  EXPECT_TRUE(r.denoise);
  EXPECT_EQ(r.aovs, kAovDenoising);
  v1::RenderSettings p = to_proto(s);
  p.set_aovs(kAovAlbedo);  // --denoise without its layers
  try {
    from_proto(p);
    ADD_FAILURE();
  } catch (const WireError& e) {
    EXPECT_NE(std::string(e.what()).find("--denoise"), std::string::npos) << e.what();
  }
  v1::Task task;
  task.set_pass_count(2);
  const Rect rect{0, 0, 3, 2};
  std::vector<PixelSums> base(12);
  base[7].r = 1;
  base[7].lum2 = 1;
  base[7].n = 1;
  task.set_base_sums(encode_sums(base));
  EXPECT_EQ(task_base(task, rect, 2).size(), 12u);
  EXPECT_EQ(task_base(task, rect, 2)[7].n, 1u);
  EXPECT_THROW(task_base(task, rect, 1), WireError);  // one plane where the data has two
}

// Issue 12 and 13's settings: camera path, fps, animation, environment.
TEST(WireSettings, SequenceAndEnvironmentSettingsRoundTrip) {
  RenderSettings s;
  s.fps = 30;
  s.animation = "walk";
  s.environment = Rgb(0.5f, 1, 2);
  s.default_environment = false;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 1, "focal_distance": 3}, {"frame": 9, "focal_distance": 5}], "turntable": {"frames": 8}})"));
  const RenderSettings r = from_proto(to_proto(s));
  EXPECT_EQ(r.fps, 30);
  EXPECT_EQ(r.animation, "walk");
  EXPECT_EQ(r.environment, s.environment);
  EXPECT_FALSE(r.default_environment);
  ASSERT_TRUE(r.camera.path);
  EXPECT_EQ(r.camera.path->to_json(), s.camera.path->to_json());
  const RenderSettings d = from_proto(to_proto(RenderSettings()));
  EXPECT_FALSE(d.environment);
  EXPECT_TRUE(d.default_environment);
  EXPECT_FALSE(d.camera.path);
  EXPECT_EQ(d.fps, 24);
  v1::RenderSettings p = to_proto(s);
  p.add_environment(1);  // four values
  EXPECT_THROW(from_proto(p), WireError);
  // An environment map is named inside the scene bundle: never a path of the receiver's.
  s.environment_map = ".tessera-env/sky.hdr";
  s.environment_strength = 0.5f;
  s.environment_rotation = 30;
  s.exposure = -3.5f;
  const RenderSettings m = from_proto(to_proto(s));
  EXPECT_EQ(m.exposure, -3.5f);
  EXPECT_EQ(m.environment_map, ".tessera-env/sky.hdr");
  EXPECT_EQ(m.environment_strength, 0.5f);
  EXPECT_EQ(m.environment_rotation, 30);
  EXPECT_EQ(d.environment_strength, 1);  // absent: 1
  for (const char* bad : {"/etc/passwd", "../../secret.hdr", ".tessera-env/../../x.hdr"}) {
    p = to_proto(s);
    p.set_environment_map(bad);
    try {
      from_proto(p);
      ADD_FAILURE() << bad;
    } catch (const WireError& e) {
      EXPECT_NE(std::string(e.what()).find("must name a file inside the scene bundle"), std::string::npos) << e.what();
    }
  }
  s.environment_map.clear();
  p = to_proto(s);
  p.set_camera_path("{\"keys\": 3}");
  try {
    from_proto(p);
    ADD_FAILURE();
  } catch (const WireError& e) {
    EXPECT_NE(std::string(e.what()).find("--camera-path"), std::string::npos) << e.what();
  }
  p = to_proto(s);
  p.set_fps(-1);
  EXPECT_THROW(from_proto(p), WireError);
}

// validate() is the one range check: each bad value is refused naming its flag.
// --light-tracer travels (coordinators refuse it for now: submission_test), and a mode the
// receiver does not know is refused by name, not cast into an enum.
TEST(WireSettings, LightTracerRoundTripsAndAnUnknownModeIsRefused) {
  RenderSettings s;
  for (const auto mode :
       {RenderSettings::LightTracer::kOff, RenderSettings::LightTracer::kOn, RenderSettings::LightTracer::kAuto}) {
    s.light_tracer = mode;
    EXPECT_EQ(from_proto(to_proto(s)).light_tracer, mode);
  }
  for (const uint32_t bad : {3u, 0xffffffffu}) {
    v1::RenderSettings p = to_proto(s);
    p.set_light_tracer(bad);
    try {
      from_proto(p);
      ADD_FAILURE() << bad;
    } catch (const WireError& e) {
      EXPECT_NE(std::string(e.what()).find("light_tracer " + std::to_string(bad) + " is not 0, 1 or 2"),
                std::string::npos)
          << e.what();
    }
  }
}

TEST(Settings, EachSettingOutOfRangeIsRefusedByItsFlag) {
  auto refused_as = [](void (*change)(RenderSettings&)) {
    RenderSettings s;
    change(s);
    try {
      s.validate();
    } catch (const SettingsError& e) {
      return e.flag();
    }
    return std::string("accepted");
  };
  EXPECT_NO_THROW(RenderSettings().validate());
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.spp = 0; }), "-s");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.spp = RenderSettings::kMaxSpp + 1; }), "-s");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.light_samples = 0; }), "-l");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.max_depth = -1; }), "-m");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.adaptive = true, s.adaptive_batch = 0; }), "-a");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.adaptive = true, s.adaptive_tolerance = -1; }), "-a");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.pass_spp = 0; }), "--pass-spp");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.tile_size = RenderSettings::kMaxTileSize + 1; }), "--tile");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.noise_target = -0.5; }), "--noise-target");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.width = 0; }), "-r");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.height = RenderSettings::kMaxImageSide + 1; }), "-r");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.lens_radius = -1; }), "-b");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.focal_distance = 0; }), "-d");
  // Found by audit: a lens of 2e18 aborted every worker that took the job (Embree's ray
  // checks), a focal distance of 1e20 gave a black image; bounded as a camera path's keys.
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.lens_radius = 2e18f; }), "-b");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.lens_radius = 1e12f; }), "accepted");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.focal_distance = 1e20f; }), "-d");
  // --env-color 1e20 times --env-strength 1e20 overflowed float: 254 of 256 samples dropped.
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.environment = Rgb(1e20f), s.environment_strength = 1e20f; }),
            "--env-strength");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.environment = Rgb(1e10f), s.environment_strength = 1e10f; }),
            "accepted");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.window = Rect{470, 0, 20, 10}; }), "-p");    // past the right edge
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.window = Rect{0, 0, 0, 0}; }), "accepted");  // the whole image
  // Issue 10, row 9: `-r 2048 2048 --tile 1` made 4 M tiles and 0.83 GB at submit.
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.width = s.camera.height = 2048, s.tile_size = 1; }), "--tile");
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.width = s.camera.height = 2048, s.tile_size = 4; }),
            "accepted");  // 262,144 tiles: the limit itself
  EXPECT_EQ(refused_as([](RenderSettings& s) { s.camera.width = s.camera.height = 65536; }), "-r");
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// AOV sums (issue 26) cross the wire exactly, and sums no render could give are refused
// before anything adds them.
TEST(WireAovs, AovSumsRoundTripAndImplausibleOnesAreRefused) {
  std::vector<AovSums> sums(37);
  for (size_t i = 0; i < sums.size(); ++i) {
    FirstHit h;
    h.hit = i % 3 != 0;
    h.distance = 1.5f * float(i);
    h.normal = Vec3(0.0f, -0.6f, 0.8f);
    h.albedo = Rgb(0.25f, 0.5f, 1.0f);
    h.material = uint32_t(i % 5);
    for (uint32_t s = 0; s < 4; ++s) sums[i].add_sample(h, 7 + s);
  }
  const std::vector<AovSums> back = decode_aovs(encode_aovs(sums), sums.size(), 4);
  for (size_t i = 0; i < sums.size(); ++i) EXPECT_TRUE(back[i] == sums[i]) << i;
  EXPECT_THROW(decode_aovs(encode_aovs(sums), sums.size(), 3), WireError);      // more samples than the task has
  EXPECT_THROW(decode_aovs(encode_aovs(sums), sums.size() + 1, 4), WireError);  // another tile's size
  std::vector<AovSums> bad = sums;
  bad[1].albedo[0] = int64_t(1) << 62;  // (would overflow the frame's sum)
  EXPECT_THROW(decode_aovs(encode_aovs(bad), bad.size(), 4), WireError);
  bad = sums;
  bad[0].hits = bad[0].n + 1;
  EXPECT_THROW(decode_aovs(encode_aovs(bad), bad.size(), 4), WireError);
  EXPECT_THROW(decode_aovs("not zstd", 1, 4), WireError);
}

// ---- splats ----

SplatLimits limits(size_t records) {
  SplatLimits l;
  l.records = records;
  l.area = 100;
  l.planes = 2;
  l.max_paths = 50;
  l.max_splats_per_path = 4;
  return l;
}

TEST(WireSplats, RecordsRoundTripBitForBit) {
  std::vector<SplatRecord> records(3);  // the middle pass traced nothing
  records[0].paths = 20;
  records[0].odd_paths = 9;
  records[0].entries = {{0, {1, 2, 3, 4}}, {7, {int64_t(1) << 40, 0, 5, int64_t(1) << 50}}, {150, {9, 9, 9, 9}}};
  records[2].paths = 1;
  records[2].entries = {{99, {0, 0, 1, 0}}};
  EXPECT_EQ(decode_splats(encode_splats(records), limits(3)), records);
}

TEST(WireSplats, WhatNoTaskCouldSendIsRefusedNamingWhy) {
  auto refused = [](std::vector<SplatRecord> records, const SplatLimits& l, const std::string& why) {
    try {
      decode_splats(encode_splats(records), l);
      ADD_FAILURE() << "accepted; expected " << why;
    } catch (const WireError& e) {
      EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
    }
  };
  SplatRecord ok;
  ok.paths = 10;
  ok.entries = {{1, {1, 1, 1, 1}}};
  refused({ok}, limits(2), "not one record per pass");
  SplatRecord r = ok;
  r.paths = 51;
  refused({r}, limits(1), "more light paths");
  r = ok;
  r.odd_paths = 11;
  refused({r}, limits(1), "more light paths");
  SplatLimits one_plane = limits(1);
  one_plane.planes = 1;
  r = ok;
  r.odd_paths = 1;
  refused({r}, one_plane, "more light paths");
  r = ok;
  r.entries = {{2, {1, 1, 1, 1}}, {2, {1, 1, 1, 1}}};
  refused({r}, limits(1), "out of order");
  r.entries = {{200, {1, 1, 1, 1}}};  // past both planes
  refused({r}, limits(1), "out of order");
  r.entries = {{2, {-1, 1, 1, 1}}};
  refused({r}, limits(1), "no light path could give");
  r.entries = {{2, {int64_t(41) << 44, 1, 1, 1}}};  // 10 paths x 4 splats of at most 2^20
  refused({r}, limits(1), "no light path could give");
  r.entries = {{2, {int64_t(1) << 24, int64_t(1) << 24, int64_t(1) << 24, int64_t(1) << 40}}};  // lum 1, lum^2 256
  refused({r}, limits(1), "a squared luminance no light path could give");
  r.entries = {{2, {int64_t(1) << 24, int64_t(1) << 24, int64_t(1) << 24, int64_t(1) << 32}}};  // lum 1, lum^2 1: fine
  EXPECT_NO_THROW(decode_splats(encode_splats({r}), limits(1)));
  r.entries = {{120, {1, 1, 1, 1}}};  // on the odd plane, with no odd paths
  refused({r}, limits(1), "no light path could give");
  // More bytes than such a task's records could fill, declared: refused before allocating.
  SplatLimits tiny = limits(1);
  tiny.max_paths = 1;
  tiny.max_splats_per_path = 1;
  std::vector<SplatRecord> big(1);
  big[0].paths = 1;
  for (uint32_t i = 0; i < 3; ++i) big[0].entries.push_back({i, {1, 1, 1, 1}});
  refused(big, tiny, "bytes declared");
  EXPECT_THROW(decode_splats("not zstd", limits(1)), WireError);
  // Headers that claim entries the bytes do not hold: refused before they are allocated.
  std::string raw(4 + 20, '\0');
  const uint32_t one = 1, claimed = 50;
  const uint64_t paths = 50;
  std::memcpy(&raw[0], &one, 4);
  std::memcpy(&raw[4], &paths, 8);
  std::memcpy(&raw[20], &claimed, 4);
  std::string z(ZSTD_compressBound(raw.size()), '\0');
  z.resize(ZSTD_compress(z.data(), z.size(), raw.data(), raw.size(), 1));
  try {
    decode_splats(z, limits(1));
    ADD_FAILURE() << "accepted entries that are not there";
  } catch (const WireError& e) {
    EXPECT_NE(std::string(e.what()).find("not the entries' size"), std::string::npos) << e.what();
  }
}

// A task's splat list: splats outside the frame's window are not seen, odd samples' light
// paths go to the second plane too, and entries come out sorted, one per index.
TEST(WireSplats, AListGathersATasksSplatsAsTheFrameWouldSeeThem) {
  SplatList list(Rect{10, 20, 4, 3}, true);
  EXPECT_TRUE(list.add(11, 21, Rgb(1, 1, 1), false));
  EXPECT_TRUE(list.add(10, 20, Rgb(0.5f, 0, 0), true));
  EXPECT_TRUE(list.add(11, 21, Rgb(1, 1, 1), false));
  EXPECT_TRUE(list.add(9, 20, Rgb(1, 1, 1), false));                // outside: not seen
  EXPECT_FALSE(list.add(10, 20, Rgb(2e6f, 0, 0), false));           // over kMaxSplatValue: dropped
  EXPECT_FALSE(list.add(10, 20, Rgb(std::nanf(""), 0, 0), false));  // not finite: dropped
  list.count_path(true);
  list.count_path(false);
  const SplatRecord r = list.take();
  EXPECT_EQ(r.paths, 2u);
  EXPECT_EQ(r.odd_paths, 1u);
  ASSERT_EQ(r.entries.size(), 3u);
  EXPECT_EQ(r.entries[0].index, 0u);
  EXPECT_EQ(r.entries[0].v[0], int64_t(1) << 23);
  EXPECT_EQ(r.entries[1].index, 5u);               // (1, 1) in the window
  EXPECT_EQ(r.entries[1].v[1], int64_t(2) << 24);  // two splats of 1
  EXPECT_EQ(r.entries[2].index, 12u);              // (0, 0) on the odd plane
  EXPECT_EQ(list.take().entries.size(), 0u);       // taken
}

// normalize() sorts a record's entries by pixel and adds those of one pixel together,
// saturating: the same sums as adding them one by one in any order (here against a map).
TEST(WireSplats, NormalizeAddsEachPixelsEntriesInAnyOrder) {
  std::mt19937_64 rng(5);
  SplatRecord r;
  std::map<uint32_t, std::array<int64_t, 4>> want;
  const int64_t big = std::numeric_limits<int64_t>::max() / 3;
  for (int i = 0; i < 20000; ++i) {
    SplatEntry e;
    e.index = uint32_t(rng() % 997);
    for (int c = 0; c < 4; ++c) e.v[c] = e.index == 7 ? big : int64_t(rng() % 1000000);  // pixel 7 saturates
    r.entries.push_back(e);
    auto& w = want[e.index];
    for (int c = 0; c < 4; ++c)
      w[c] = w[c] > std::numeric_limits<int64_t>::max() - e.v[c] ? std::numeric_limits<int64_t>::max() : w[c] + e.v[c];
  }
  r.normalize();
  ASSERT_EQ(r.entries.size(), want.size());
  size_t k = 0;
  for (const auto& [index, sums] : want) {
    ASSERT_EQ(r.entries[k].index, index);
    for (int c = 0; c < 4; ++c) EXPECT_EQ(r.entries[k].v[c], sums[c]) << index;
    ++k;
  }
  EXPECT_EQ(r.entries[7].v[0], std::numeric_limits<int64_t>::max());
}

// A splat's squared luminance, the variance layer's: most of CBspheres' splats are 2^-9 to
// 2^-7 at 480x360 (smaller at lower resolutions), and 2^-12 units rounded every splat
// under about 0.011 to no variance. Now every splat keeps it to half a unit (2^-33), and
// the brightest (2^20) add the cap rather than wrap.
TEST(WireSplats, EvenADimSplatAddsItsVariance) {
  for (const float v : {0x1p-13f, 0.001f, 0.004f, 0.011f, 0.3f, 7.0f}) {
    int64_t units[4];
    ASSERT_TRUE(splat_units(Rgb(v, v, v), units));
    const double lum = Rgb(v).luminance(), lum2 = lum * lum;
    EXPECT_NEAR(double(units[3]) / SplatSums::kLum2Unit, lum2, 0.5 / SplatSums::kLum2Unit) << v;
    EXPECT_GT(units[3], 0) << v;
  }
  int64_t units[4];
  ASSERT_TRUE(splat_units(Rgb(SplatSink::kMaxSplatValue), units));
  EXPECT_EQ(units[3], SplatSums::kMaxLum2Units);
  SplatList list(Rect{0, 0, 2, 1}, false);
  for (int i = 0; i < 3; ++i) list.add(0, 0, Rgb(SplatSink::kMaxSplatValue), false);
  list.count_path(false);
  EXPECT_EQ(list.take().entries[0].v[3], std::numeric_limits<int64_t>::max());  // saturated
}

}  // namespace
}  // namespace tessera
