// The render farm as a user runs it: a real coordinator and workers on 127.0.0.1, driven
// through the tessera CLI; every image equal to tessera render's, bit for bit.
#include <fmt/format.h>

#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

TEST_F(Farm, OneTwoAndThreeWorkersGiveTheBytesOfTessearRender) {
  const std::string local = local_render(kFlags);
  start_coordinator();
  for (int n = 1; n <= 3; ++n) {
    start_worker();
    const std::string out = (dir / ("farm" + std::to_string(n) + ".exr")).string();
    const CommandResult r = submit_wait(kScene, kFlags, out);
    ASSERT_EQ(r.code, 0) << r.err << r.out;
    EXPECT_NE(r.out.find("DONE"), std::string::npos) << r.out;
    expect_same_pixels(local, out);
  }
}

// Every render setting crosses the wire: a noise target (judged per tile, so the tile size
// matters too) and the estimator switches give the farm exactly `tessera render`'s image.
// Issue 12: a frame of a sequence (--frame N) is the same image rendered alone or through
// the farm, and carries its number in the EXR.
TEST_F(Farm, AFrameNumberGivesTheSameImageLocallyAndThroughTheFarm) {
  const std::string out = farm_gives_the_local_image(kFlags + " --frame 12");
  EXPECT_EQ(read_exr(out).metadata.at("tessera/frame"), "12");
  EXPECT_EQ(read_exr((dir / "local.exr").string()).metadata.at("tessera/frame"), "12");
  const CommandResult bad = run("render " + kScene + " -r 8 8 --frame 2000000 -q", dir);
  EXPECT_NE(bad.code, 0);  // refused like every setting out of range, naming the flag
  EXPECT_NE(bad.err.find("--frame: must be in -1000000..1000000"), std::string::npos) << bad.err;
}

// Issue 12: a sequence with a camera path (a focus pull while the camera turns) through a
// farm that loses a worker mid-job: every frame is tessera render's frame, bit for bit, and
// a frame rendered alone is the same frame again. submit --wait writes each frame's file.
TEST_F(Farm, ASequenceThroughAFarmLosingAWorkerGivesEveryFrameOfTesseraRender) {
  const std::string path = (dir / "path.json").string();
  std::ofstream(path) << R"({"keys": [{"frame": 1, "lens_radius": 0.05, "focal_distance": 3},
                                      {"frame": 4, "focal_distance": 6}],
                             "turntable": {"frames": 16}})";
  const std::string flags = "-r 96 72 -s 16 --pass-spp 8 -m 6 --seed 5 --tile 16 --camera-path " + path;
  const CommandResult local =
      run("render " + kScene + " " + flags + " --frames 1-4 -q -f " + (dir / "local.####.exr").string(), dir);
  ASSERT_EQ(local.code, 0) << local.err;
  auto local_frame = [&](int n) {
    char name[32];
    std::snprintf(name, sizeof name, "local.%04d.exr", n);
    return (dir / name).string();
  };
  const CommandResult alone =
      run("render " + kScene + " " + flags + " --frame 3 -q -f " + (dir / "alone.exr").string(), dir);
  ASSERT_EQ(alone.code, 0) << alone.err;
  expect_same_pixels(local_frame(3), (dir / "alone.exr").string());

  start_coordinator("127.0.0.1:0", "1");
  Process& victim = start_worker();
  start_worker();
  const CommandResult sub =
      run("submit " + kScene + " " + flags + " --frames 1-4 --coordinator " + grpc_addr + " --json", dir);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = nlohmann::json::parse(sub.out).at("id");
  ASSERT_TRUE(kill_while_it_renders(victim, 2000));
  const CommandResult w = run("watch " + id + " --coordinator " + grpc_addr, dir);
  ASSERT_EQ(w.code, 0) << w.err << w.out;
  EXPECT_NE(w.out.find("frames 4/4"), std::string::npos) << w.out;
  const CommandResult st = run("status " + id + " --coordinator " + grpc_addr, dir);
  EXPECT_NE(st.out.find("frames: done 1-4"), std::string::npos) << st.out;
  const CommandResult all = run(
      "fetch " + id + " --all -f " + (dir / "farm.####.exr").string() + " --coordinator " + grpc_addr + " --json", dir);
  ASSERT_EQ(all.code, 0) << all.err;
  const nlohmann::json fetched = nlohmann::json::parse(all.out);  // (it printed nothing with --json)
  EXPECT_EQ(fetched.at("frames_total"), 4);
  ASSERT_EQ(fetched.at("written").size(), 4u);
  EXPECT_EQ(fetched.at("written").at(1).at("frame"), 2);
  EXPECT_EQ(fetched.at("written").at(1).at("files").at(0), (dir / "farm.0002.exr").string());
  for (int n = 1; n <= 4; ++n) {
    char name[32];
    std::snprintf(name, sizeof name, "farm.%04d.exr", n);
    expect_same_pixels(local_frame(n), (dir / name).string());
    EXPECT_EQ(read_exr((dir / name).string()).metadata.at("tessera/frame"), std::to_string(n));
    EXPECT_EQ(read_exr((dir / name).string()).metadata.at("tessera/time"), fmt::format("{}", n / 24.0));
  }
  const nlohmann::json seq = get_json("/api/jobs/" + id);  // the live page's view of it
  ASSERT_EQ(seq.at("frames").size(), 4u) << seq;
  EXPECT_EQ(seq.at("frames").at(1).at("state"), "DONE");
  httplib::Client http("127.0.0.1", http_port);
  const auto preview =
      http.Get(("/jobs/" + seq.at("frames").at(1).at("job_id").get<std::string>() + "/preview.png").c_str());
  ASSERT_TRUE(preview && preview->status == 200);
  EXPECT_EQ(preview->body.substr(1, 3), "PNG");
  const CommandResult one = run(
      "fetch " + id + " --frame 2 -f " + (dir / "two.png").string() + " --coordinator " + grpc_addr + " --json", dir);
  EXPECT_EQ(one.code, 0) << one.err;
  EXPECT_TRUE(fs::exists(dir / "two.png"));
  const nlohmann::json got = nlohmann::json::parse(one.out);
  EXPECT_EQ(got.at("frame"), 2);
  EXPECT_EQ(got.at("files"), nlohmann::json::array({(dir / "two.png").string()}));
  const CommandResult none =
      run("fetch " + id + " -f " + (dir / "x.exr").string() + " --coordinator " + grpc_addr, dir);
  EXPECT_NE(none.code, 0);
  EXPECT_NE(none.err.find("--frame N"), std::string::npos) << none.err;

  // submit --wait writes each frame as it finishes.
  const CommandResult waited = submit_wait(kScene, flags + " --frames 3,4", (dir / "wait.####.exr").string());
  ASSERT_EQ(waited.code, 0) << waited.err << waited.out;
  expect_same_pixels(local_frame(3), (dir / "wait.0003.exr").string());
  expect_same_pixels(local_frame(4), (dir / "wait.0004.exr").string());
  const CommandResult no_hashes = submit_wait(kScene, flags + " --frames 3,4", (dir / "wait.exr").string());
  EXPECT_NE(no_hashes.code, 0) << no_hashes.err;
  EXPECT_NE(no_hashes.err.find("#### in every -f path"), std::string::npos) << no_hashes.err;
}

// Issue 12: an animated glTF scene's frames through the farm are tessera render's frames.
TEST_F(Farm, AnAnimatedGltfSequenceThroughTheFarmGivesTesseraRendersFrames) {
  const std::string scene = std::string(TESSERA_SOURCE_DIR) + "/scenes/cornell-animated.gltf";
  const std::string flags = "-r 64 48 -s 8 --pass-spp 4 -m 6 --tile 16";
  const CommandResult local =
      run("render " + scene + " " + flags + " --frames 6,30 -q -f " + (dir / "local.####.exr").string(), dir);
  ASSERT_EQ(local.code, 0) << local.err;
  start_coordinator();
  start_worker();
  start_worker();
  const CommandResult r = submit_wait(scene, flags + " --frames 6,30", (dir / "farm.####.exr").string());
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  for (const char* n : {"0006", "0030"})
    expect_same_pixels((dir / ("local." + std::string(n) + ".exr")).string(),
                       (dir / ("farm." + std::string(n) + ".exr")).string());
  const CommandResult bad =
      submit_wait(scene, flags + " --frames 1,2 --animation walk", (dir / "bad.####.exr").string());
  EXPECT_NE(bad.code, 0);  // refused at submit, naming the animation
  EXPECT_NE((bad.err + bad.out).find("no animation 'walk'"), std::string::npos) << bad.err << bad.out;
}

// Issue 29: a skinned bar bending and a floor morphing (scenes/skinned-bar.gltf): the
// farm's frames are tessera render's, bit for bit.
TEST_F(Farm, ASkinnedAndMorphedSequenceThroughTheFarmGivesTesseraRendersFrames) {
  const std::string scene = std::string(TESSERA_SOURCE_DIR) + "/scenes/skinned-bar.gltf";
  const std::string flags = "-r 64 48 -s 8 --pass-spp 4 -m 6 --tile 16 --frames 12,40";
  const CommandResult local = run("render " + scene + " " + flags + " -q -f " + (dir / "local.####.exr").string(), dir);
  ASSERT_EQ(local.code, 0) << local.err;
  start_coordinator();
  start_worker();
  const CommandResult r = submit_wait(scene, flags, (dir / "farm.####.exr").string());
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  // The client says what a local render says before it starts: the scene's warnings and lighting.
  EXPECT_NE(r.err.find("tessera: lighting: the default environment (uniform radiance 1)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("tessera: warning: "), std::string::npos) << r.err;
  for (const char* n : {"0012", "0040"})
    expect_same_pixels((dir / ("local." + std::string(n) + ".exr")).string(),
                       (dir / ("farm." + std::string(n) + ".exr")).string());
}

// Issue 13's first piece: a uniform environment (--env-color) crosses the wire and the
// farm's image is still tessera render's, on a CS184 scene.
TEST_F(Farm, AnEnvironmentLightGivesTheLocalImageThroughTheFarm) {
  farm_gives_the_local_image("-r 64 48 -s 16 --pass-spp 8 -m 6 --env-color 0.2 0.3 0.4");
}

// An image environment (--env, from another folder than the scene's) travels in the scene
// bundle: the farm's image is the local one, rotated and scaled alike.
TEST_F(Farm, AnEnvironmentMapTravelsWithTheSceneAndGivesTheLocalImage) {
  farm_gives_the_local_image("-r 64 48 -s 16 --pass-spp 8 -m 6 --env " + std::string(TESSERA_SOURCE_DIR) +
                             "/scenes/sky.hdr --env-rotate 30 --env-strength 0.5");
  // A broken map is refused at submit, named as the job named it.
  const std::string bad = (dir / "bad.hdr").string();
  std::ofstream(bad) << "not radiance";
  const CommandResult refused = submit_wait(kScene, "-r 8 8 -s 1 --env " + bad, (dir / "bad.exr").string());
  EXPECT_NE(refused.code, 0);
  EXPECT_NE(refused.err.find("--env: .tessera-env/bad.hdr: not a Radiance HDR image"), std::string::npos)
      << refused.err;
}

TEST_F(Farm, NoiseTargetAndEstimatorSwitchesGiveTheLocalImage) {
  const std::string flags = "-r 96 72 -s 64 --pass-spp 8 -m 6 --tile 24 --noise-target 0.2 --no-mis";
  const std::string local = local_render(flags);
  start_coordinator();
  start_worker(2);
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, flags, out, "--json");
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json status = nlohmann::json::parse(r.out);
  // (--json prints 64-bit counts as numbers)
  EXPECT_LT(status["samples_done"].get<uint64_t>(), status["samples_total"].get<uint64_t>());  // tiles stopped early
  EXPECT_TRUE(status["settings"]["no_mis"].get<bool>());
  expect_same_pixels(local, out);
}

// Odd tiles that do not divide the frame, adaptive sampling, and workers of different
// thread counts taking rows of several tasks at once: still the local image.
TEST_F(Farm, OddTilesAdaptiveSamplingAndUnequalWorkersGiveTheLocalImage) {
  const std::string flags = "-r 90 70 -s 48 -a 8 0.1 -m 6 --tile 13 --seed 3";
  const std::string local = local_render(flags);
  start_coordinator();
  start_worker(2);
  start_worker(1);
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(kScene, flags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
}

TEST_F(Farm, GltfSceneThroughTheFarmMatchesTheLocalRender) {
  const std::string scene = std::string(TESSERA_SOURCE_DIR) + "/scenes/dof-row.gltf";
  const std::string flags = "-r 96 64 -s 8 --pass-spp 4 -b 0.1 -d 7";
  const std::string local = (dir / "local.exr").string();
  ASSERT_EQ(run("render " + scene + " " + flags + " -q -f " + local, dir).code, 0);
  start_coordinator();
  start_worker(2);
  const std::string out = (dir / "farm.exr").string();
  const CommandResult r = submit_wait(scene, flags, out);
  ASSERT_EQ(r.code, 0) << r.err;
  expect_same_pixels(local, out);
}

TEST_F(Farm, CancelStopsWorkAndKeepsTheImage) {
  start_coordinator();
  start_worker();
  const CommandResult sub = run("submit " + kScene + " -r 320 240 -s 4096 --coordinator " + grpc_addr, dir);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = sub.out.substr(0, sub.out.find('\n'));
  nlohmann::json job;
  for (int i = 0; i < 500; ++i) {  // wait for some samples
    job = get_json("/api/jobs/" + id);
    if (job != nullptr && std::stoull(job["samples_done"].get<std::string>()) > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  const CommandResult c = run("cancel " + id + " --coordinator " + grpc_addr + " --json", dir);
  ASSERT_EQ(c.code, 0) << c.err;
  EXPECT_EQ(nlohmann::json::parse(c.out)["state"], "CANCELLED");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const nlohmann::json before = get_json("/api/status");
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const nlohmann::json after = get_json("/api/status");
  ASSERT_TRUE(before.is_object() && after.is_object()) << before << after;
  ASSERT_EQ(after.at("jobs").size(), 1u) << after;
  EXPECT_EQ(before.at("jobs").at(0).at("samples_done"), after.at("jobs").at(0).at("samples_done"));  // no more work
  ASSERT_EQ(after.at("workers").size(), 1u) << after;
  EXPECT_EQ(after.at("workers").at(0).at("active"), false);
  const std::string out = (dir / "cancelled.exr").string();
  ASSERT_EQ(run("fetch " + id + " -f " + out + " --coordinator " + grpc_addr, dir).code, 0);
  const ExrImage img = read_exr(out);
  float spp = 0;
  for (float n : img.channels.at("spp")) spp += n;
  EXPECT_GT(spp, 0);  // what was rendered before the cancel is kept
}

TEST_F(Farm, MalformedSceneIsRefusedAtSubmitAndTheCoordinatorKeepsServing) {
  start_coordinator();
  start_worker();
  const fs::path bad = dir / "broken.dae";
  std::ofstream(bad) << "<COLLADA><asset><up_axis>Q_UP</up_axis></asset></COLLADA>";
  const CommandResult r = run("submit " + bad.string() + " --coordinator " + grpc_addr, dir);
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("broken.dae"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("unknown up_axis 'Q_UP'"), std::string::npos) << r.err;
  const CommandResult ok = submit_wait(kScene, "-r 32 24 -s 4", (dir / "ok.exr").string());
  EXPECT_EQ(ok.code, 0) << ok.err;
}

TEST_F(Farm, WorkerStopsCleanlyOnSigtermAndGivesItsLeaseBack) {
  start_coordinator();
  Process& w = start_worker();
  // One tile, one pass of 4096 spp: the worker is surely mid-tile when the signal comes.
  ASSERT_EQ(
      run("submit " + kScene + " -r 64 48 -s 4096 --pass-spp 4096 --tile 64 --coordinator " + grpc_addr, dir).code, 0);
  for (int i = 0; i < 500; ++i) {
    const nlohmann::json s = get_json("/api/status");
    if (s != nullptr && !s["workers"].empty() && s["workers"][0]["active"].get<bool>()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto t0 = std::chrono::steady_clock::now();
  w.signal(SIGTERM);
  EXPECT_EQ(w.wait(10), 0);
  // Abandons the tile (finishing it would take over 10 s); the render checks per pixel.
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 3.0);
  httplib::Client cli("127.0.0.1", http_port);
  const std::string metrics = cli.Get("/metrics")->body;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(metrics, m, std::regex("tessera_leases_released_total (\\d+)"))) << metrics;
  EXPECT_GE(std::stoi(m[1]), 1);  // the abandoned tile (and a prefetched one, if any)
  EXPECT_NE(metrics.find("tessera_workers_busy 0"), std::string::npos) << metrics;  // no lease left held
  EXPECT_NE(metrics.find("\ntessera_workers 0\n"), std::string::npos) << metrics;   // and it left at once
}

// kill -9 of the coordinator before the first merge, mid-pass and in the middle of writing
// a checkpoint; each time it is started again on the same data folder and port. The
// workers and the waiting client carry on by themselves, and the image is still the bytes
// of `tessera render`.

}  // namespace
}  // namespace tessera
