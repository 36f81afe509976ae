// The render farm as a user runs it: a real coordinator and workers on 127.0.0.1 with
// ports picked by the system, driven through the tessera CLI and the status endpoint.
#include <gtest/gtest.h>
#include <httplib.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <sstream>
#include <thread>

#include "core/io/image_io.h"
#include "tests/integration/farm_helpers.h"
#include "tests/integration/process.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::Process;

using testing::CommandResult;
using testing::expect_same_pixels;
using testing::kBin;
using testing::kScene;
using testing::slurp;

CommandResult run(const std::string& args, const fs::path& dir) {
  const std::string out = (dir / "cmd.out").string(), err = (dir / "cmd.err").string();
  const int status = std::system((kBin + "/tessera " + args + " >" + out + " 2>" + err).c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out), slurp(err)};
}

class Farm : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_farm_" + std::to_string(::getpid()) + "_" +
                                              ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::unique_ptr<Process> coordinator;
  std::vector<std::unique_ptr<Process>> workers;
  std::string grpc_addr;
  int http_port = 0;
  int coordinators = 0;  // started so far: each writes its own log

  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override {
    workers.clear();
    coordinator.reset();
    if (!std::getenv("TESSERA_KEEP_TEST_DIR")) fs::remove_all(dir);
  }
  void start_coordinator(const std::string& listen = "127.0.0.1:0", const std::string& lease = "2",
                         const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args{
        "--listen",        listen, "--http",           "127.0.0.1:0", "--data", (dir / "data").string(),
        "--lease-seconds", lease,  "--image-interval", "0.2"};
    args.insert(args.end(), extra.begin(), extra.end());
    coordinator = std::make_unique<Process>(kBin + "/tessera-coordinator", args,
                                            (dir / ("coordinator" + std::to_string(++coordinators) + ".err")).string());
    const std::string g = coordinator->read_line(), h = coordinator->read_line();
    std::smatch m;
    ASSERT_TRUE(std::regex_match(g, m, std::regex("grpc listening on (127\\.0\\.0\\.1:\\d+)"))) << g;
    grpc_addr = m[1];
    ASSERT_TRUE(std::regex_match(h, m, std::regex("http listening on 127\\.0\\.0\\.1:(\\d+)"))) << h;
    http_port = std::stoi(m[1]);
  }
  Process& start_worker(int threads = 1, const std::vector<std::string>& extra = {}) {
    const std::string n = std::to_string(workers.size());
    std::vector<std::string> args{
        "--coordinator", grpc_addr, "--threads", std::to_string(threads), "--cache", (dir / ("cache" + n)).string(),
        "--name",        "w" + n};
    args.insert(args.end(), extra.begin(), extra.end());
    workers.push_back(
        std::make_unique<Process>(kBin + "/tessera-worker", args, (dir / ("worker" + n + ".err")).string()));
    return *workers.back();
  }
  nlohmann::json get_json(const std::string& path) {
    httplib::Client cli("127.0.0.1", http_port);
    auto res = cli.Get(path.c_str());
    if (!res || res->status != 200) return nullptr;
    return nlohmann::json::parse(res->body);
  }
  // Kills worker w0 (`victim`) with SIGKILL while it holds a lease, once the first job has
  // merged some work; polls the status endpoint up to `tries` times, 5 ms apart.
  bool kill_while_it_renders(Process& victim, int tries) {
    for (int i = 0; i < tries; ++i) {
      const nlohmann::json s = get_json("/api/status");
      if (s != nullptr && !s["jobs"].empty() && std::stoull(s["jobs"][0]["samples_done"].get<std::string>()) > 0)
        for (const auto& w : s["workers"])
          if (w["name"] == "w0" && w["active"].get<bool>()) {
            victim.signal(SIGKILL);
            return true;
          }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return false;
  }
  // `tessera submit SCENE FLAGS --wait -q EXTRA -f OUT` against this test's coordinator.
  CommandResult submit_wait(const std::string& scene, const std::string& flags, const std::string& out,
                            const std::string& extra = "") {
    return run("submit " + scene + " " + flags + " --coordinator " + grpc_addr + " --wait -q " + extra + " -f " + out,
               dir);
  }
  std::string local_render(const std::string& flags) {
    const std::string out = (dir / "local.exr").string();
    const CommandResult r = run("render " + kScene + " " + flags + " -q -f " + out, dir);
    EXPECT_EQ(r.code, 0) << r.err;
    return out;
  }
  // Renders kScene with `flags` locally, then through a new coordinator and two workers,
  // and expects the same pixels. Returns the farm's image (the coordinator stays up).
  std::string farm_gives_the_local_image(const std::string& flags) {
    const std::string local = local_render(flags);
    start_coordinator();
    start_worker();
    start_worker();
    const std::string out = (dir / "farm.exr").string();
    const CommandResult r = submit_wait(kScene, flags, out);
    EXPECT_EQ(r.code, 0) << r.err;
    expect_same_pixels(local, out);
    return out;
  }
};

const std::string kFlags = "-r 96 72 -s 24 --pass-spp 8 -m 6 --seed 11 --tile 16";

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
  const CommandResult all =
      run("fetch " + id + " --all -f " + (dir / "farm.####.exr").string() + " --coordinator " + grpc_addr, dir);
  ASSERT_EQ(all.code, 0) << all.err;
  for (int n = 1; n <= 4; ++n) {
    char name[32];
    std::snprintf(name, sizeof name, "farm.%04d.exr", n);
    expect_same_pixels(local_frame(n), (dir / name).string());
    EXPECT_EQ(read_exr((dir / name).string()).metadata.at("tessera/frame"), std::to_string(n));
    EXPECT_EQ(read_exr((dir / name).string()).metadata.at("tessera/time"), std::to_string(n / 24.0));
  }
  const nlohmann::json seq = get_json("/api/jobs/" + id);  // the live page's view of it
  ASSERT_EQ(seq.at("frames").size(), 4u) << seq;
  EXPECT_EQ(seq.at("frames").at(1).at("state"), "DONE");
  httplib::Client http("127.0.0.1", http_port);
  const auto preview =
      http.Get(("/jobs/" + seq.at("frames").at(1).at("job_id").get<std::string>() + "/preview.png").c_str());
  ASSERT_TRUE(preview && preview->status == 200);
  EXPECT_EQ(preview->body.substr(1, 3), "PNG");
  const CommandResult one =
      run("fetch " + id + " --frame 2 -f " + (dir / "two.png").string() + " --coordinator " + grpc_addr, dir);
  EXPECT_EQ(one.code, 0) << one.err;
  EXPECT_TRUE(fs::exists(dir / "two.png"));
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
  EXPECT_LT(std::stoull(status["samples_done"].get<std::string>()),
            std::stoull(status["samples_total"].get<std::string>()));  // tiles stopped early
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

TEST_F(Farm, WorkerKilledMidTileChangesNothing) {
  const std::string flags = "-r 160 120 -s 32 --pass-spp 8 -m 6 --seed 5";
  const std::string local = local_render(flags);
  start_coordinator("127.0.0.1:0", "1");
  Process& victim = start_worker();
  start_worker();
  const CommandResult sub = run("submit " + kScene + " " + flags + " --coordinator " + grpc_addr + " --json", dir);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = nlohmann::json::parse(sub.out).at("id");
  // Kill the victim while it holds a lease, once some work has been merged.
  ASSERT_TRUE(kill_while_it_renders(victim, 1000));
  const CommandResult w = run("watch " + id + " --coordinator " + grpc_addr + " --json", dir);
  ASSERT_EQ(w.code, 0) << w.err;
  const std::string out = (dir / "farm.exr").string();
  ASSERT_EQ(run("fetch " + id + " -f " + out + " --coordinator " + grpc_addr, dir).code, 0);
  expect_same_pixels(local, out);
  httplib::Client cli("127.0.0.1", http_port);
  const std::string metrics = cli.Get("/metrics")->body;
  EXPECT_NE(metrics.find("tessera_results_merged_total"), std::string::npos);
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

TEST_F(Farm, StatusEndpointJsonMetricsPreviewAndPage) {
  start_coordinator();
  start_worker();
  const CommandResult r = submit_wait(kScene, "-r 64 48 -s 8 --tile 16", (dir / "x.png").string());
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json s = get_json("/api/status");
  ASSERT_NE(s, nullptr);
  ASSERT_EQ(s["jobs"].size(), 1u);
  const std::string id = s["jobs"][0]["id"];
  EXPECT_EQ(s["jobs"][0]["state"], "DONE");
  EXPECT_EQ(s["workers"].size(), 1u);
  EXPECT_GT(s["workers"][0]["samples_per_second"].get<double>(), 0);
  // The worker reported its render threads' time: busy part of it, never more than all.
  const double busy = s["workers"][0]["busy_thread_seconds"], total = s["workers"][0]["thread_seconds"];
  EXPECT_GT(busy, 0);
  EXPECT_LE(busy, total);
  EXPECT_GT(s["workers"][0]["utilization"].get<double>(), 0);
  EXPECT_LE(s["workers"][0]["utilization"].get<double>(), 1);
  const nlohmann::json j = get_json("/api/jobs/" + id);
  EXPECT_EQ(j["tiles"].size(), size_t(4 * 3));  // 64x48 in 16-pixel tiles
  EXPECT_EQ(get_json("/api/jobs/no-such-job"), nullptr);
  httplib::Client cli("127.0.0.1", http_port);
  // Prometheus text: comments, or `name{labels} value` with a numeric value.
  const std::string metrics = cli.Get("/metrics")->body;
  std::istringstream lines(metrics);
  int samples = 0;
  for (std::string line; std::getline(lines, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::smatch m;
    ASSERT_TRUE(std::regex_match(line, m, std::regex(R"(([a-z_]+)(\{[a-z_]+="[a-z0-9]+"\})? (-?[0-9.e+-]+))"))) << line;
    std::stod(m[3]);
    ++samples;
  }
  EXPECT_GT(samples, 10);
  EXPECT_NE(metrics.find("tessera_jobs{state=\"done\"} 1"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_worker_utilization{worker=\""), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_workers_utilization "), std::string::npos) << metrics;
  // Autoscaling signals (issue 11): nothing left once the job is done.
  EXPECT_NE(metrics.find("tessera_queue_tasks{state=\"ready\"} 0"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_remaining_core_seconds 0"), std::string::npos) << metrics;
  EXPECT_NE(metrics.find("tessera_thread_samples_per_second "), std::string::npos) << metrics;
  // Probes for Kubernetes.
  EXPECT_EQ(cli.Get("/healthz")->status, 200);
  const auto ready = cli.Get("/readyz");
  EXPECT_EQ(ready->status, 200);
  EXPECT_EQ(ready->body, "ready\n");
  const auto png = cli.Get(("/jobs/" + id + "/preview.png").c_str());
  ASSERT_TRUE(png);
  EXPECT_EQ(png->status, 200);
  EXPECT_EQ(png->body.substr(1, 3), "PNG");
  const auto page = cli.Get("/");
  EXPECT_NE(page->body.find("<canvas"), std::string::npos);
  // Issue 10, row 8: names went into innerHTML as they were, with no policy. Now the page
  // has no inline script, a policy that forbids it, and every value written as markup is
  // escaped.
  const std::string csp = page->get_header_value("Content-Security-Policy");
  EXPECT_NE(csp.find("default-src 'none'"), std::string::npos) << csp;
  EXPECT_NE(csp.find("script-src 'self';"), std::string::npos) << csp;  // no 'unsafe-inline'
  EXPECT_EQ(csp.find("unsafe"), std::string::npos) << csp;
  EXPECT_EQ(page->body.find("<script>"), std::string::npos);
  EXPECT_EQ(png->get_header_value("X-Content-Type-Options"), "nosniff");
  const auto js = cli.Get("/app.js");
  ASSERT_TRUE(js);
  EXPECT_EQ(js->status, 200);
  std::istringstream script(js->body);
  int markup_lines = 0;
  for (std::string line; std::getline(script, line);) {
    if (line.find("innerHTML") == std::string::npos && line.find("<td>") == std::string::npos) continue;
    ++markup_lines;
    for (size_t at = line.find("${"); at != std::string::npos; at = line.find("${", at + 2))
      EXPECT_EQ(line.compare(at + 2, 4, "esc("), 0) << "unescaped value in markup: " << line.substr(at, 40);
  }
  EXPECT_GE(markup_lines, 4);
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
TEST_F(Farm, CoordinatorKilledAtAnyMomentLosesNothingAndTheImageIsUnchanged) {
  const std::string flags = "-r 160 120 -s 256 --pass-spp 8 -m 6 --seed 5";
  const std::string local = local_render(flags);
  const std::vector<std::string> crashy{"--checkpoint-seconds", "0.3", "--test-checkpoint-delay-ms", "250"};
  start_coordinator("127.0.0.1:0", "2", crashy);
  const std::string addr = grpc_addr;
  const std::string out = (dir / "farm.exr").string();
  Process client(kBin + "/tessera",
                 {"submit", kScene, "-r", "160", "120", "-s", "256", "--pass-spp", "8", "-m", "6", "--seed", "5",
                  "--coordinator", addr, "--wait", "-q", "-f", out},
                 (dir / "client.err").string());
  auto job = [&]() -> nlohmann::json {
    const nlohmann::json s = get_json("/api/status");
    return s == nullptr || s["jobs"].empty() ? nlohmann::json() : s["jobs"][0];
  };
  auto samples = [&](const nlohmann::json& j) { return std::stoull(j["samples_done"].get<std::string>()); };
  auto wait_for = [&](const std::function<bool()>& ok) {
    for (int i = 0; i < 3000; ++i) {
      if (ok()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return false;
  };
  auto crash_and_restart = [&] {
    coordinator->signal(SIGKILL);
    ASSERT_EQ(coordinator->wait(10), -SIGKILL);
    start_coordinator(addr, "2", crashy);
    ASSERT_EQ(grpc_addr, addr);
  };
  // 1. Accepted, nothing rendered: no workers yet. (Killed only once the client has the
  // job's id: a submit whose answer is lost is not retried, since it could run the job
  // twice, so the client would stop there.)
  ASSERT_TRUE(wait_for([&] { return slurp((dir / "client.err").string()).find("submitted") != std::string::npos; }));
  ASSERT_TRUE(wait_for([&] { return !job().is_null(); }));
  const std::string id = job()["id"];
  crash_and_restart();
  ASSERT_FALSE(job().is_null());
  EXPECT_EQ(job()["id"], id);
  EXPECT_EQ(job()["state"], "QUEUED");
  start_worker();
  start_worker();
  // 2. Mid-pass, after a checkpoint: the restarted one starts from it.
  const fs::path checkpoint = dir / "data" / "jobs" / id / "checkpoint";
  ASSERT_TRUE(wait_for([&] { return fs::exists(checkpoint) && samples(job()) > 0; }));
  crash_and_restart();
  ASSERT_FALSE(job().is_null());
  EXPECT_GT(samples(job()), 0u);  // taken up from the checkpoint, not from nothing
  EXPECT_EQ(job()["state"], "RUNNING");
  // 3. While a checkpoint is being written (its temporary file is there, not yet renamed).
  ASSERT_TRUE(wait_for([&] { return fs::exists(checkpoint.string() + ".tmp"); }));
  crash_and_restart();
  ASSERT_FALSE(job().is_null());
  // The client reconnects by itself and fetches the finished image.
  ASSERT_EQ(client.wait(120), 0) << slurp((dir / "client.err").string());
  expect_same_pixels(local, out);
  EXPECT_EQ(job()["state"], "DONE");
  // Once more with the job done: it stays done, and its image can still be fetched.
  crash_and_restart();
  EXPECT_EQ(job()["state"], "DONE");
  const std::string again = (dir / "again.exr").string();
  ASSERT_EQ(run("fetch " + id + " -f " + again + " --coordinator " + addr, dir).code, 0);
  expect_same_pixels(local, again);
}

// Issue 12 with issue 10: a coordinator killed mid-sequence (one frame done, the next
// checkpointed mid-pass) and restarted goes on; `submit --wait` rides it out and writes
// every frame, each bit for bit tessera render's.
TEST_F(Farm, CoordinatorKilledMidSequenceLosesNoFrame) {
  const std::string flags = "-r 96 72 -s 64 --pass-spp 8 -m 6 --seed 9";
  const CommandResult local =
      run("render " + kScene + " " + flags + " --frames 1-3 -q -f " + (dir / "local.####.exr").string(), dir);
  ASSERT_EQ(local.code, 0) << local.err;
  const std::vector<std::string> crashy{"--checkpoint-seconds", "0.2"};
  start_coordinator("127.0.0.1:0", "2", crashy);
  const std::string addr = grpc_addr;
  start_worker();
  Process client(kBin + "/tessera",
                 {"submit",
                  kScene,
                  "-r",
                  "96",
                  "72",
                  "-s",
                  "64",
                  "--pass-spp",
                  "8",
                  "-m",
                  "6",
                  "--seed",
                  "9",
                  "--frames",
                  "1-3",
                  "--coordinator",
                  addr,
                  "--wait",
                  "-q",
                  "-f",
                  (dir / "farm.####.exr").string()},
                 (dir / "client.err").string());
  auto job = [&]() -> nlohmann::json {
    const nlohmann::json st = get_json("/api/status");
    if (st == nullptr || st["jobs"].empty()) return nlohmann::json();
    return get_json("/api/jobs/" + st["jobs"][0]["id"].get<std::string>());
  };
  // Frame 1 done and frame 2 checkpointed mid-pass. (Frame 1's final checkpoint is written
  // just after DONE shows; if the kill comes first, frame 1 goes on from its previous
  // checkpoint: the same bits either way.)
  bool ready = false;
  for (int i = 0; i < 6000 && !ready; ++i) {
    const nlohmann::json j = job();
    if (j != nullptr && j.contains("frames") && j["frames"][0]["state"] == "DONE") {
      const std::string f2 = j["frames"][1].value("job_id", "");
      ready = !f2.empty() && fs::exists(dir / "data" / "jobs" / f2 / "checkpoint");
    }
    if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(ready);
  coordinator->signal(SIGKILL);
  ASSERT_EQ(coordinator->wait(10), -SIGKILL);
  start_coordinator(addr, "2", crashy);
  const nlohmann::json after = job();
  ASSERT_NE(after, nullptr);
  EXPECT_NE(after["frames"][0]["state"], "QUEUED");  // taken up from its checkpoint
  EXPECT_NE(after["frames"][1]["state"], "QUEUED");
  ASSERT_EQ(client.wait(180), 0) << slurp((dir / "client.err").string());
  for (const char* n : {"0001", "0002", "0003"})
    expect_same_pixels((dir / ("local." + std::string(n) + ".exr")).string(),
                       (dir / ("farm." + std::string(n) + ".exr")).string());
}

// For batch allocations (Slurm): a worker with --exit-when-idle leaves cleanly once the
// queue has been empty that long, and not while there is work.
TEST_F(Farm, WorkerWithExitWhenIdleLeavesOnceTheQueueIsEmpty) {
  start_coordinator();
  Process& w = start_worker(1, {"--exit-when-idle", "3"});
  const CommandResult r = submit_wait(kScene, "-r 64 48 -s 16 --pass-spp 4", (dir / "idle.exr").string());
  ASSERT_EQ(r.code, 0) << r.err;  // it stayed while there was work
  EXPECT_EQ(w.wait(20), 0);
  EXPECT_NE(slurp((dir / "worker0.err").string()).find("--exit-when-idle"), std::string::npos);
  const nlohmann::json s = get_json("/api/status");
  EXPECT_TRUE(s["workers"].empty()) << s.dump();  // it said goodbye
}

// A coordinator that cannot be reached has no work either: an idle batch worker leaves.
TEST_F(Farm, WorkerWithExitWhenIdleLeavesWhenTheCoordinatorIsUnreachable) {
  grpc_addr = "127.0.0.1:1";  // nothing listens there
  Process& w = start_worker(1, {"--exit-when-idle", "1"});
  EXPECT_EQ(w.wait(20), 0);
  EXPECT_NE(slurp((dir / "worker0.err").string()).find("unreachable"), std::string::npos);
}

TEST_F(Farm, WorkerReconnectsWhenTheCoordinatorComesBack) {
  start_coordinator();
  const std::string addr = grpc_addr;
  start_worker();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  coordinator->signal(SIGTERM);
  ASSERT_EQ(coordinator->wait(10), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  start_coordinator(addr);  // same port: the worker finds it again
  ASSERT_EQ(grpc_addr, addr);
  const CommandResult r = submit_wait(kScene, "-r 32 24 -s 4", (dir / "again.exr").string());
  EXPECT_EQ(r.code, 0) << r.err;
}

}  // namespace
}  // namespace tessera
