// The farm across a long link (issue 30): workers reaching the coordinator through a relay
// that delays every byte (bench/wan/wan_link.h), next to one on loopback. What is tested is
// what must hold at any distance: the image is tessera render's, the far worker does its
// share and reports its round trip, and a connection cut mid-result loses nothing. Speed
// is measured by bench/farm_wan.sh, not here.
#include "bench/wan/wan_link.h"
#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

class FarmWan : public Farm {
 protected:
  // A worker named `name` reaching the coordinator through `link`.
  Process& start_far_worker(const wan::WanLink& link, const std::string& name) {
    workers.push_back(std::make_unique<Process>(
        kBin + "/tessera-worker",
        std::vector<std::string>{"--coordinator", "127.0.0.1:" + std::to_string(link.port()), "--threads", "1",
                                 "--cache", (dir / ("cache-" + name)).string(), "--name", name},
        (dir / ("worker-" + name + ".err")).string()));
    return *workers.back();
  }
  int grpc_port() const { return std::stoi(grpc_addr.substr(grpc_addr.rfind(':') + 1)); }
  nlohmann::json worker_status(const std::string& name) {
    const nlohmann::json s = get_json("/api/status");
    if (s != nullptr)
      for (const auto& w : s["workers"])
        if (w["name"] == name) return w;
    return nullptr;
  }
  std::string submit(const std::string& flags) {
    const CommandResult sub = run("submit " + kScene + " " + flags + " --coordinator " + grpc_addr + " --json", dir);
    EXPECT_EQ(sub.code, 0) << sub.err;
    return sub.code == 0 ? nlohmann::json::parse(sub.out).at("id").get<std::string>() : "";
  }
  // Waits for the job's end, fetches its image and expects tessera render's pixels.
  void expect_local_image(const std::string& id, const std::string& local) {
    const CommandResult w = run("watch " + id + " --coordinator " + grpc_addr + " --json", dir);
    ASSERT_EQ(w.code, 0) << w.err;
    const std::string out = (dir / "farm.exr").string();
    ASSERT_EQ(run("fetch " + id + " -f " + out + " --coordinator " + grpc_addr, dir).code, 0);
    expect_same_pixels(local, out);
  }
};

TEST_F(FarmWan, AWorker20MsAwayAndOneNextDoorGiveTesseraRendersImage) {
  const std::string flags = "-r 160 120 -s 128 --pass-spp 8 -m 6 --seed 3";
  const std::string local = local_render(flags);
  start_coordinator("127.0.0.1:0", "2");
  wan::WanLink link("127.0.0.1", grpc_port(), {0.010, 0});  // 20 ms round trip
  start_far_worker(link, "far");
  start_worker();  // "w1", next door
  const std::string id = submit(flags);
  ASSERT_FALSE(id.empty());
  // The far worker measures its round trip and reports it with its heartbeats.
  double round_trip_ms = 0;
  for (int i = 0; i < 400 && round_trip_ms <= 0; ++i) {
    const nlohmann::json w = worker_status("far");
    if (w != nullptr) round_trip_ms = w["round_trip_ms"].get<double>();
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  }
  EXPECT_GE(round_trip_ms, 20);
  EXPECT_LT(round_trip_ms, 2000);
  expect_local_image(id, local);
  for (const std::string name : {"far", "w1"}) {  // both did their part, and the link's load is counted
    const nlohmann::json w = worker_status(name);
    ASSERT_NE(w, nullptr) << name;
    EXPECT_GT(w["tasks_done"].get<uint64_t>(), 0u) << name;
    EXPECT_GT(w["bytes_per_sample"].get<double>(), 0) << name;
  }
  EXPECT_GT(link.bytes_up(), 0u);
}

TEST_F(FarmWan, AConnectionCutMidResultLosesNothing) {
  const std::string flags = "-r 160 120 -s 64 --pass-spp 8 -m 6 --seed 4";
  const std::string local = local_render(flags);
  start_coordinator("127.0.0.1:0", "2");
  wan::WanLink link("127.0.0.1", grpc_port(), {0.005, 0});
  start_far_worker(link, "far");
  const std::string id = submit(flags);
  ASSERT_FALSE(id.empty());
  // Once results flow, cut the link within the next few kilobytes the worker sends:
  // results are most of those bytes, so the cut lands inside one.
  for (int i = 0; i < 400; ++i) {
    const nlohmann::json w = worker_status("far");
    if (w != nullptr && w["tasks_done"].get<uint64_t>() > 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  link.cut_after_upload(3000);
  expect_local_image(id, local);
  EXPECT_GE(link.connections_accepted(), 2);  // cut, and connected again
}

// A link far narrower than the worker's results (2 Mbit/s; a pass of this frame is tens of
// kilobytes of sums, rendered in tens of milliseconds): the worker sees its results queue,
// asks for runs of passes, and sends a tile's sums once for several passes, from the
// tile's first pass or from its sums so far. The image is still tessera render's.
TEST_F(FarmWan, AWorkerOnANarrowLinkSendsRunsOfPassesAndTheImageIsTesseraRenders) {
  const std::string flags = "-r 120 90 -s 96 --pass-spp 6 -m 6 --seed 5";
  const std::string local = local_render(flags);
  start_coordinator("127.0.0.1:0", "2");
  wan::WanLink link("127.0.0.1", grpc_port(), {0.002, 250000});
  start_far_worker(link, "narrow");
  const std::string id = submit(flags);
  ASSERT_FALSE(id.empty());
  expect_local_image(id, local);
  const nlohmann::json w = worker_status("narrow");
  ASSERT_NE(w, nullptr);
  EXPECT_GE(w["passes_per_task"].get<uint32_t>(), 2u);
  const std::string log = slurp((dir / "worker-narrow.err").string());
  EXPECT_NE(log.find("results outrun the link"), std::string::npos) << log;
}

}  // namespace
}  // namespace tessera
