// The Farm fixture the farm_*_test.cc files share: a real coordinator and workers on
// 127.0.0.1 with ports picked by the system, started and stopped per test, driven through
// the tessera CLI.
#pragma once

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

namespace fs = std::filesystem;
using testing::Process;

using testing::CommandResult;
using testing::expect_same_pixels;
using testing::kBin;
using testing::kScene;
using testing::slurp;

inline CommandResult run(const std::string& args, const fs::path& dir) {
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
    std::vector<std::string> args{"--listen",
                                  listen,
                                  "--http",
                                  "127.0.0.1:0",
                                  "--data",
                                  (dir / "data").string(),
                                  "--lease-seconds",
                                  lease,
                                  "--image-interval-seconds",
                                  "0.2"};
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
  // The samples the first job of a status has merged; nothing when it lists no job.
  static std::optional<uint64_t> first_job_samples(const nlohmann::json& status) {
    if (status == nullptr || status["jobs"].empty()) return std::nullopt;
    return std::stoull(status["jobs"][0]["samples_done"].get<std::string>());
  }
  // `tessera submit kScene FLAGS --coordinator (this one) --wait -q -f OUT`, left running
  // (its errors in client.err).
  std::unique_ptr<Process> submit_in_background(const std::string& flags, const std::string& out) {
    std::vector<std::string> args{"submit", kScene};
    std::istringstream words(flags);
    for (std::string w; words >> w;) args.push_back(w);
    for (const std::string& w :
         {std::string("--coordinator"), grpc_addr, std::string("--wait"), std::string("-q"), std::string("-f"), out})
      args.push_back(w);
    return std::make_unique<Process>(kBin + "/tessera", args, (dir / "client.err").string());
  }
  // The coordinator's tessera_checkpoints_written_total (0 if it cannot say).
  uint64_t checkpoints_written() {
    httplib::Client cli("127.0.0.1", http_port);
    auto res = cli.Get("/metrics");
    const std::string key = "\ntessera_checkpoints_written_total ";
    const size_t at = res && res->status == 200 ? res->body.find(key) : std::string::npos;
    return at == std::string::npos ? 0 : std::stoull(res->body.substr(at + key.size()));
  }
  // Once the first job has merged more than `above` samples and two checkpoints have been
  // written since (one at a time: the second began after it had merged; --checkpoint-seconds
  // 0.2, waited for, not slept on: under load they once took more than the half second
  // slept before), SIGKILLs the coordinator and starts it
  // again on its address and folder with `extra`; it must go on from its checkpoint.
  void crash_coordinator_mid_job(uint64_t above, const std::vector<std::string>& extra) {
    bool merged = false;
    for (int i = 0; i < 2000 && !merged; ++i) {
      const std::optional<uint64_t> n = first_job_samples(get_json("/api/status"));
      merged = n && *n > above;
      if (!merged) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ASSERT_TRUE(merged);
    const uint64_t before = checkpoints_written();
    for (int i = 0; i < 3000 && checkpoints_written() <= before + 1; ++i)  // the second began after `merged`
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const std::string addr = grpc_addr;
    coordinator->signal(SIGKILL);
    ASSERT_EQ(coordinator->wait(10), -SIGKILL);
    start_coordinator(addr, "2", extra);
    ASSERT_EQ(grpc_addr, addr);
    const std::optional<uint64_t> restored = first_job_samples(get_json("/api/status"));
    ASSERT_TRUE(restored);
    EXPECT_GT(*restored, 0u);
  }
  // Kills worker w0 (`victim`) with SIGKILL while it holds a lease, once the first job has
  // merged some work; polls the status endpoint up to `tries` times, 5 ms apart.
  bool kill_while_it_renders(Process& victim, int tries) {
    for (int i = 0; i < tries; ++i) {
      const nlohmann::json s = get_json("/api/status");
      if (first_job_samples(s).value_or(0) > 0)
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

}  // namespace tessera
