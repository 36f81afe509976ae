// The farm client tests' fixture: a coordinator served on loopback in this process, a
// worker on demand, and what the commands print captured (farm_client_test.cc,
// farm_watch_test.cc).
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "client/farm_client.h"
#include "server/grpc_services.h"
#include "tests/core/test_paths.h"
#include "worker/worker.h"

namespace tessera {

namespace fs = std::filesystem;

// Captures what a command prints.
class Output {
 public:
  Output() : f_(std::tmpfile()) {}
  ~Output() { std::fclose(f_); }
  std::FILE* file() { return f_; }
  std::string text() {
    std::fflush(f_);
    std::rewind(f_);
    std::string s;
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof buf, f_)) > 0;) s.append(buf, n);
    return s;
  }

 private:
  std::FILE* f_;
};

class FarmClient : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_client_" + std::to_string(::getpid()));
  std::unique_ptr<Coordinator> coordinator;
  std::unique_ptr<ClientService> client_service;
  std::unique_ptr<WorkerService> worker_service;
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<v1::Tessera::StubInterface> stub;
  std::atomic<bool> stop_worker{false};
  std::thread worker;
  std::string address;
  Output out, err;
  FarmContext ctx;
  static constexpr size_t kSceneChunk = 16 << 10;  // scenes to workers in pieces of 16 KiB
  int max_message_bytes = 0;                       // > 0: the server's limit, each way

  void SetUp() override {
    CoordinatorOptions o;
    o.data_dir = (dir / "data").string();
    o.image_interval_seconds = 0;
    o.image_chunk_bytes = 4096;  // images come in many pieces (FetchImageChunks)
    o.scene_chunk_bytes = kSceneChunk;
    coordinator = std::make_unique<Coordinator>(o);
    client_service = std::make_unique<ClientService>(*coordinator);
    worker_service = std::make_unique<WorkerService>(*coordinator);
    const int port = serve(0);
    ASSERT_GT(port, 0);
    address = "127.0.0.1:" + std::to_string(port);
    stub = connect_coordinator(address);
    ctx.coordinator = address;
    ctx.quiet = true;
    ctx.out = out.file();
    ctx.err = err.file();
  }
  // Serves the coordinator on `port` (0: a free one); returns the port.
  int serve(int port) {
    grpc::ServerBuilder b;
    int bound = 0;
    b.AddListeningPort("127.0.0.1:" + std::to_string(port), grpc::InsecureServerCredentials(), &bound);
    b.RegisterService(client_service.get());
    b.RegisterService(worker_service.get());
    if (max_message_bytes > 0) configure_server(b, max_message_bytes);
    server = b.BuildAndStart();
    return bound;
  }
  void start_worker() {
    worker = std::thread([this] {
      WorkerOptions w;
      w.coordinator = address;
      w.threads = 2;
      w.cache_dir = (dir / "cache").string();
      Worker(w).run(stop_worker);
    });
  }
  void TearDown() override {
    stop_worker = true;
    if (worker.joinable()) worker.join();
    server->Shutdown();
    fs::remove_all(dir);
  }
  SubmitRequest request(const std::vector<std::string>& outputs) {
    SubmitRequest r;
    r.flags.scene = testing::source_path("scenes/cornell-spheres.dae");
    r.flags.resolution = {40, 30};
    r.flags.settings.spp = 8;
    r.flags.settings.pass_spp = 4;
    r.flags.settings.max_depth = 4;
    r.flags.settings.tile_size = 16;
    r.flags.outputs = outputs;
    return r;
  }
};

}  // namespace tessera
