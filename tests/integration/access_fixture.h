// The Access tests' farm (access_test.cc, liar_test.cc): a coordinator with a tokens file
// of every role, workers and `tessera` commands each with its token from a file, on loopback.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <httplib.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <regex>
#include <string>
#include <vector>

#include "core/io/files.h"
#include "tessera.grpc.pb.h"
#include "tests/integration/farm_helpers.h"
#include "tests/integration/process.h"
#include "wire.h"

namespace tessera {

namespace fs = std::filesystem;

// A gRPC call made with a token, and a worker's registration: for the tests that speak to
// the worker service themselves.
inline std::unique_ptr<grpc::ClientContext> call(const char* token) {
  auto c = std::make_unique<grpc::ClientContext>();
  c->AddMetadata("authorization", std::string("Bearer ") + token);
  return c;
}
inline v1::RegisterRequest registration() {
  v1::RegisterRequest reg;
  reg.set_version(kProtocolVersion);
  reg.set_name("w");
  reg.set_threads(1);
  return reg;
}

using testing::CommandResult;
using testing::expect_same_pixels;
using testing::kBin;
using testing::kScene;
using testing::Process;
using testing::slurp;

constexpr const char* kAlice = "alice-client-token-0123456789";
constexpr const char* kBob = "bob-client-token-0123456789ab";
constexpr const char* kWorker = "worker-token-0123456789abcdef";
constexpr const char* kViewer = "viewer-token-0123456789abcdef";
constexpr const char* kAdmin = "admin-token-0123456789abcdefg";
constexpr const char* kMallory = "mallory-worker-token-0123456789";
constexpr const char* kEnrol = "enrol-token-0123456789abcdefgh";
const std::string kFlags = "-r 48 36 -s 8 --pass-spp 4 -m 4 --seed 2 --tile 16";

class Access : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_access_" + std::to_string(::getpid()) + "_" +
                                              ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::unique_ptr<Process> coordinator;
  std::vector<std::unique_ptr<Process>> workers;
  std::string grpc_addr;
  int http_port = 0;

  void SetUp() override {
    fs::create_directories(dir);
    write_file_atomic((dir / "tokens").string(),
                      std::string("# role name token\n") + "client alice " + kAlice + "\nclient bob " + kBob +
                          "\nworker farm " + kWorker + "\nviewer ops " + kViewer + "\nadmin root " + kAdmin +
                          "\nworker mallory " + kMallory + "\nenrol farm-enrol " + kEnrol + "\n");
  }
  void TearDown() override {
    workers.clear();
    coordinator.reset();
    if (!std::getenv("TESSERA_KEEP_TEST_DIR")) fs::remove_all(dir);  // (as farm_fixture.h)
  }
  std::string token_file(const char* token) {
    const std::string path = (dir / (std::string(token).substr(0, 5) + ".token")).string();
    write_file_atomic(path, std::string(token) + "\n");
    return path;
  }
  void start_coordinator(std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--listen", "127.0.0.1:0",           "--http",        "127.0.0.1:0",
                                  "--data",   (dir / "data").string(), "--tokens-file", (dir / "tokens").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    coordinator = std::make_unique<Process>(kBin + "/tessera-coordinator", args, (dir / "coordinator.err").string());
    const std::string g = coordinator->read_line(), h = coordinator->read_line();
    std::smatch m;
    ASSERT_TRUE(std::regex_search(g, m, std::regex("grpc listening on (127\\.0\\.0\\.1:\\d+)"))) << g;
    grpc_addr = m[1];
    ASSERT_TRUE(std::regex_search(h, m, std::regex("http listening on 127\\.0\\.0\\.1:(\\d+)"))) << h;
    http_port = std::stoi(m[1]);
  }
  Process& start_worker(const char* token, const std::string& extra_flag = "", const std::string& extra_value = "") {
    std::vector<std::string> extra;
    if (!extra_flag.empty()) extra = {extra_flag, extra_value};
    return start_worker(token, extra);
  }
  Process& start_worker(const char* token, const std::vector<std::string>& extra) {
    std::vector<std::string> args{"--token-file", token_file(token)};
    args.insert(args.end(), extra.begin(), extra.end());
    return spawn_worker(args);
  }
  // A worker that enrols as `name` with the enrolment token (as the deploy recipes run them).
  Process& start_enrolled(const std::string& name, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args{"--enrol-token-file", token_file(kEnrol), "--name", name};
    args.insert(args.end(), extra.begin(), extra.end());
    return spawn_worker(args);
  }
  // A one-thread worker of this coordinator with `args` besides; its stderr in workerN.err.
  Process& spawn_worker(const std::vector<std::string>& args) {
    std::vector<std::string> all{"--coordinator", grpc_addr, "--threads", "1", "--cache", (dir / "cache").string()};
    all.insert(all.end(), args.begin(), args.end());
    const std::string n = std::to_string(workers.size());
    workers.push_back(
        std::make_unique<Process>(kBin + "/tessera-worker", all, (dir / ("worker" + n + ".err")).string()));
    return *workers.back();
  }
  // `tessera ARGS --coordinator ADDR`, with the token (if any) from a file.
  CommandResult tessera(const std::string& args, const char* token, const std::string& extra = "") {
    const std::string out = (dir / "cmd.out").string(), err = (dir / "cmd.err").string();
    std::string cmd = kBin + "/tessera " + args + " --coordinator " + grpc_addr + " " + extra;
    if (token) cmd += " --token-file " + token_file(token);
    const int status =
        std::system(("env -u TESSERA_TOKEN -u TESSERA_TOKEN_FILE " + cmd + " >" + out + " 2>" + err).c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out), slurp(err)};
  }
  std::string submit(const char* token) {
    const CommandResult r = tessera("submit " + kScene + " " + kFlags, token);
    EXPECT_EQ(r.code, 0) << r.err;
    std::string id = r.out;
    id.erase(id.find_last_not_of('\n') + 1);
    return id;
  }
  int http_get(const std::string& path, const std::string& authorization, std::string* www = nullptr) {
    httplib::Client cli("127.0.0.1", http_port);
    httplib::Headers h;
    if (!authorization.empty()) h.emplace("Authorization", authorization);
    auto res = cli.Get(path.c_str(), h);
    if (!res) return -1;
    if (www) *www = res->get_header_value("WWW-Authenticate");
    return res->status;
  }
};

}  // namespace tessera
