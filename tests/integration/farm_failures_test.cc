// The farm when things fail: workers and the coordinator killed at any moment, workers
// leaving when idle or when the coordinator is gone, and reconnecting when it is back.
#include <unistd.h>

#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

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

// A scene within every load bound can still cost hours a sample. A task held past
// --max-task-seconds fails on its worker, which is told to stop rendering it; once that
// happened on two workers the job fails naming the bound, and both workers are idle again.
TEST_F(Farm, ATaskPastTheTaskBoundFailsTheJobAndItsWorkersStopRenderingIt) {
  start_coordinator("127.0.0.1:0", "2", {"--max-task-seconds", "0.3"});
  const Process& a = start_worker();
  const Process& b = start_worker();
  // One task of 32 x 32 pixels x 8192 samples: about 12 s on one thread here.
  const CommandResult r =
      submit_wait(kScene, "-r 32 32 --tile 32 -s 8192 --pass-spp 8192", (dir / "slow.exr").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("0.3 s (--max-task-seconds)"), std::string::npos) << r.err;
  auto cpu_ticks = [](pid_t pid) {  // user + system time (/proc/PID/stat fields 14 and 15)
    std::istringstream in(slurp("/proc/" + std::to_string(pid) + "/stat"));
    std::string field;
    long ticks = 0;
    for (int i = 1; i <= 15 && in >> field; ++i)
      if (i >= 14) ticks += std::stol(field);
    return ticks;
  };
  // Told at their next heartbeat (every 2 s here), they stop within a pixel.
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  const long before = cpu_ticks(a.pid()) + cpu_ticks(b.pid());
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  const long used = cpu_ticks(a.pid()) + cpu_ticks(b.pid()) - before;
  EXPECT_LT(used, sysconf(_SC_CLK_TCK) / 2) << "ticks of CPU in 1.5 s: still rendering";
}

// The daemons' flags refuse values out of their range, naming the flag, before anything
// starts. Found by rereading: CLI11's Range lets "nan" through (every comparison with NaN
// is false), so `--lease-seconds nan` started a coordinator whose leases never expired, and
// a NaN GiB bound was cast to an integer; floating-point flags check tessera::finite_range.
TEST_F(Farm, TheDaemonsFlagsRefuseValuesOutOfRangeAndNaN) {
  const std::vector<std::pair<std::string, std::vector<std::string>>> bad = {
      {"tessera-coordinator", {"--max-task-seconds", "-1"}},
      {"tessera-coordinator", {"--max-task-seconds", "nan"}},
      {"tessera-coordinator", {"--lease-seconds", "nan"}},
      {"tessera-coordinator", {"--image-interval-seconds", "-1"}},
      {"tessera-coordinator", {"--max-scene-loads", "0"}},
      {"tessera-worker", {"--coordinator", "127.0.0.1:1", "--cache-max-gib", "-1"}},
      {"tessera-worker", {"--coordinator", "127.0.0.1:1", "--max-memory-gib", "nan"}},
      {"tessera-worker", {"--coordinator", "127.0.0.1:1", "--lookahead-seconds", "1e400"}},
  };
  for (const auto& [binary, args] : bad) {
    const std::string err = (dir / "bad.err").string(), flag = args[args.size() - 2];
    Process p(kBin + "/" + binary, args, err);
    EXPECT_EQ(p.wait(10), 2) << binary << " " << flag << " " << args.back();
    EXPECT_NE(slurp(err).find(flag + ": Value " + args.back()), std::string::npos) << slurp(err);
  }
}

// For batch allocations (Slurm): a worker with --exit-when-idle-seconds leaves cleanly once the
// queue has been empty that long, and not while there is work.
TEST_F(Farm, WorkerWithExitWhenIdleLeavesOnceTheQueueIsEmpty) {
  start_coordinator();
  Process& w = start_worker(1, {"--exit-when-idle-seconds", "3"});
  const CommandResult r = submit_wait(kScene, "-r 64 48 -s 16 --pass-spp 4", (dir / "idle.exr").string());
  ASSERT_EQ(r.code, 0) << r.err;  // it stayed while there was work
  EXPECT_EQ(w.wait(20), 0);
  EXPECT_NE(slurp((dir / "worker0.err").string()).find("--exit-when-idle-seconds"), std::string::npos);
  const nlohmann::json s = get_json("/api/status");
  EXPECT_TRUE(s["workers"].empty()) << s.dump();  // it said goodbye
}

// A coordinator that cannot be reached has no work either: an idle batch worker leaves.
TEST_F(Farm, WorkerWithExitWhenIdleLeavesWhenTheCoordinatorIsUnreachable) {
  grpc_addr = "127.0.0.1:1";  // nothing listens there
  Process& w = start_worker(1, {"--exit-when-idle-seconds", "1"});
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
