// The farm across machines, for real: the coordinator and each worker in a network
// namespace of its own (its own loopback, its own address), joined by veth pairs to a
// bridge in the coordinator's namespace. The test makes the namespaces with `ip netns`
// and removes them; it skips, saying why, where the kernel or the user may not.
//
// Addresses are from 192.0.2.0/24 (TEST-NET-1, reserved for documentation): they exist
// only inside these namespaces, which have no route anywhere else.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <sstream>
#include <thread>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "tests/integration/farm_helpers.h"
#include "tests/integration/process.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::Process;

using testing::expect_same_pixels;
using testing::kBin;
using testing::kScene;
using testing::slurp;

int sh(const std::string& cmd) {
  const int status = std::system((cmd + " >/dev/null 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Three hosts: "c" (coordinator and client, with the bridge, 192.0.2.1) and "w1", "w2"
// (workers, 192.0.2.11 and .12). Removed, with their links, when the object goes away.
class Hosts {
 public:
  Hosts() : prefix_("ts" + std::to_string(::getpid() % 100000)) {}
  ~Hosts() {
    for (const char* h : {"w1", "w2", "c"}) sh("ip netns del " + ns(h));
  }
  std::string ns(const std::string& host) const { return prefix_ + host; }
  // Empty on success, else why the machine refused.
  std::string make() {
    if (geteuid() != 0) return "not root: ip netns needs CAP_SYS_ADMIN";
    if (sh("ip netns add " + ns("c")) != 0) return "'ip netns add' refused (no network namespaces here)";
    std::vector<std::string> steps = {
        "ip -n " + ns("c") + " link set lo up",
        "ip -n " + ns("c") + " link add br0 type bridge",
        "ip -n " + ns("c") + " addr add 192.0.2.1/24 dev br0",
        "ip -n " + ns("c") + " link set br0 up",
    };
    for (const auto& [host, addr] : {std::pair{"w1", "192.0.2.11"}, std::pair{"w2", "192.0.2.12"}}) {
      const std::string h = host;
      steps.push_back("ip netns add " + ns(h));
      steps.push_back("ip -n " + ns(h) + " link set lo up");
      // One end in the worker's namespace, the other on the coordinator's bridge.
      steps.push_back("ip link add " + ns(h) + "a netns " + ns(h) + " type veth peer name " + ns(h) + "b netns " +
                      ns("c"));
      steps.push_back("ip -n " + ns(h) + " addr add " + addr + "/24 dev " + ns(h) + "a");
      steps.push_back("ip -n " + ns(h) + " link set " + ns(h) + "a up");
      steps.push_back("ip -n " + ns("c") + " link set " + ns(h) + "b master br0");
      steps.push_back("ip -n " + ns("c") + " link set " + ns(h) + "b up");
    }
    for (const std::string& s : steps)
      if (sh(s) != 0) return "'" + s + "' failed";
    return "";
  }
  // Cuts a worker off: its end of the link goes down.
  void unplug(const std::string& host) { sh("ip -n " + ns(host) + " link set " + ns(host) + "a down"); }

 private:
  std::string prefix_;
};

constexpr const char* kClientToken = "client-token-0123456789abcdef";
constexpr const char* kWorkerToken = "worker-token-0123456789abcdef";
constexpr const char* kViewerToken = "viewer-token-0123456789abcdef";

class NetnsFarm : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_netns_" + std::to_string(::getpid()));
  Hosts hosts;
  void SetUp() override {
    fs::create_directories(dir);
    const std::string refused = hosts.make();
    if (!refused.empty()) GTEST_SKIP() << "network namespaces unavailable: " << refused << "; skipping";
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir);
  }
  std::vector<std::string> in(const std::string& host, const std::vector<std::string>& argv) {
    std::vector<std::string> a{"netns", "exec", hosts.ns(host)};
    a.insert(a.end(), argv.begin(), argv.end());
    return a;
  }
  // A file holding the token of `role` ("client" or "worker").
  std::string token_file(const std::string& role) {
    const std::string path = (dir / (role + ".token")).string();
    write_file_atomic(path, role == "client" ? kClientToken : kWorkerToken);
    return path;
  }
  // `tessera ARGS` on host c, as the client "alice"; returns stdout, asserting success.
  std::string tessera(const std::string& args) {
    const std::string out = (dir / "cmd.out").string(), err = (dir / "cmd.err").string();
    const int status = std::system(("ip netns exec " + hosts.ns("c") + " " + kBin + "/tessera " + args +
                                    " --token-file " + token_file("client") + " >" + out + " 2>" + err)
                                       .c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << args << ": " << slurp(err);
    return slurp(out);
  }
};

TEST_F(NetnsFarm, TwoMachinesRenderTheLocalImageAndOneLosingItsLinkChangesNothing) {
  // Beyond loopback, as on real machines: with access tokens (the coordinator refuses to
  // listen there without them).
  write_file_atomic((dir / "tokens").string(), "client alice " + std::string(kClientToken) + "\nworker farm " +
                                                   kWorkerToken + "\nviewer ops " + kViewerToken + "\n");
  const std::string flags = "-r 96 72 -s 512 --pass-spp 8 -m 6 --tile 16 --seed 5";
  const std::string local = (dir / "local.exr").string();
  ASSERT_EQ(sh(kBin + "/tessera render " + kScene + " " + flags + " -q -f " + local), 0);

  Process coordinator(
      "/usr/sbin/ip",
      in("c", {kBin + "/tessera-coordinator", "--listen", "192.0.2.1:0", "--http", "127.0.0.1:0", "--data",
               (dir / "data").string(), "--lease-seconds", "2", "--tokens-file", (dir / "tokens").string()}),
      (dir / "coordinator.err").string());
  std::smatch m;
  const std::string line = coordinator.read_line();
  ASSERT_TRUE(std::regex_match(line, m, std::regex("grpc listening on (192\\.0\\.2\\.1:\\d+)"))) << line;
  const std::string addr = m[1];
  const std::string http = coordinator.read_line();
  ASSERT_TRUE(std::regex_match(http, m, std::regex("http listening on (127\\.0\\.0\\.1:\\d+)"))) << http;
  const std::string metrics_url = "http://" + std::string(m[1]) + "/metrics";
  std::vector<std::unique_ptr<Process>> workers;
  for (const char* h : {"w1", "w2"})
    workers.push_back(std::make_unique<Process>(
        "/usr/sbin/ip",
        in(h, {kBin + "/tessera-worker", "--coordinator", addr, "--threads", "1", "--cache",
               (dir / (std::string("cache-") + h)).string(), "--name", h, "-v", "--token-file", token_file("worker")}),
        (dir / (std::string("worker-") + h + ".err")).string()));

  // The scene reaches the workers only over the wire: submitted from a copy that is gone
  // before any worker could read it.
  const fs::path copy = dir / "submitted" / "scene.dae";
  fs::create_directories(copy.parent_path());
  fs::copy_file(kScene, copy);
  std::string id = tessera("submit " + copy.string() + " " + flags + " --coordinator " + addr);
  id.erase(id.find_last_not_of('\n') + 1);
  fs::remove_all(copy.parent_path());

  // Both machines at work, then one loses its link mid-job.
  nlohmann::json st;
  for (int i = 0; i < 600; ++i) {
    st = nlohmann::json::parse(tessera("status " + id + " --json --coordinator " + addr));
    if (st["samples_done"].get<uint64_t>() * 5 > st["samples_total"].get<uint64_t>()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(st["state"], "RUNNING") << st.dump();
  EXPECT_EQ(st["active_workers"], 2) << st.dump();
  hosts.unplug("w1");

  const nlohmann::json done = nlohmann::json::parse(tessera("watch " + id + " --json --coordinator " + addr));
  EXPECT_EQ(done["state"], "DONE") << done.dump();
  const std::string farm = (dir / "farm.exr").string();
  tessera("fetch " + id + " -f " + farm + " --coordinator " + addr);
  expect_same_pixels(local, farm);
  // The cut-off worker held leases: they expired, and their tiles were rendered again.
  const std::string metrics = (dir / "metrics.txt").string();
  const std::string fetch_metrics = "import urllib.request; r = urllib.request.Request('" + metrics_url +
                                    "', headers={'Authorization': 'Bearer " + kViewerToken +
                                    "'}); print(urllib.request.urlopen(r).read().decode())";
  ASSERT_EQ(
      std::system(("ip netns exec " + hosts.ns("c") + " python3 -c \"" + fetch_metrics + "\" > " + metrics).c_str()),
      0);
  const std::string metrics_text = slurp(metrics);
  ASSERT_TRUE(std::regex_search(metrics_text, m, std::regex("tessera_leases_expired_total (\\d+)"))) << metrics_text;
  EXPECT_GE(std::stoi(m[1]), 1);
  // Each worker fetched the scene into its own cache.
  for (const char* h : {"w1", "w2"}) {
    bool cached = false;
    for (const auto& e : fs::recursive_directory_iterator(dir / (std::string("cache-") + h)))
      cached |= e.path().filename() == "scene.dae";
    EXPECT_TRUE(cached) << h;
  }
}

}  // namespace
}  // namespace tessera
