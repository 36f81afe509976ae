// tessera-coordinator: splits frames into tiles, leases them to workers, merges results.
#include <grpcpp/grpcpp.h>
#include <signal.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cstdio>
#include <thread>

#include "server/grpc_services.h"
#include "server/status_http.h"

namespace {

std::pair<std::string, int> split_host_port(const std::string& s, const char* flag) {
  const size_t colon = s.rfind(':');
  if (colon == std::string::npos) throw CLI::ValidationError(flag, "expected HOST:PORT, got '" + s + "'");
  try {
    const int port = std::stoi(s.substr(colon + 1));
    if (port < 0 || port > 65535) throw std::out_of_range("port");
    return {s.substr(0, colon), port};
  } catch (const std::exception&) {
    throw CLI::ValidationError(flag, "bad port in '" + s + "'");
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tessera-coordinator: the render farm's coordinator"};
  std::string listen = "127.0.0.1:7878", http = "127.0.0.1:7879";
  tessera::CoordinatorOptions opt;
  app.add_option("--listen", listen, "gRPC address HOST:PORT (port 0 picks a free port)")->capture_default_str();
  app.add_option("--http", http, "status endpoint HOST:PORT (port 0 picks a free port)")->capture_default_str();
  app.add_option("--data", opt.data_dir, "data directory (scenes, progressive images)")->capture_default_str();
  app.add_option("--lease-seconds", opt.lease_seconds, "lease length; a silent worker's task moves on after it")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 3600.0));
  app.add_option("--max-workers", opt.max_workers, "registered workers at most (silent ones are forgotten after 60 s)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--image-interval", opt.image_interval_seconds, "write progressive images at most this often (s)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  opt.heartbeat_seconds = std::min(2.0, opt.lease_seconds / 4);

  // Block the stop signals in every thread; main waits for them below.
  sigset_t sigs;
  sigemptyset(&sigs);
  sigaddset(&sigs, SIGINT);
  sigaddset(&sigs, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &sigs, nullptr);

  try {
    const auto [grpc_host, grpc_port] = split_host_port(listen, "--listen");
    const auto [http_host, http_port] = split_host_port(http, "--http");
    tessera::Coordinator coordinator(opt);
    tessera::ClientService client(coordinator);
    tessera::WorkerService worker(coordinator);
    grpc::ServerBuilder builder;
    int bound = 0;
    builder.AddListeningPort(grpc_host + ":" + std::to_string(grpc_port), grpc::InsecureServerCredentials(), &bound);
    builder.SetMaxReceiveMessageSize(tessera::kMaxMessageBytes);
    builder.SetMaxSendMessageSize(tessera::kMaxMessageBytes);
    builder.RegisterService(&client);
    builder.RegisterService(&worker);
    std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
    if (!server || bound == 0) {
      std::fprintf(stderr, "tessera-coordinator: error: cannot listen on %s\n", listen.c_str());
      return 1;
    }
    tessera::StatusHttp status(coordinator);
    const int http_bound = status.bind(http_host, http_port);
    status.start();
    std::printf("grpc listening on %s:%d\n", grpc_host.c_str(), bound);
    std::printf("http listening on %s:%d\n", http_host.c_str(), http_bound);
    std::fflush(stdout);

    std::atomic<bool> stopping{false};
    std::thread reaper([&] {  // leases also expire when no worker is asking for work
      while (!stopping) {
        coordinator.expire_leases();
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      }
    });
    int sig = 0;
    sigwait(&sigs, &sig);
    std::fprintf(stderr, "tessera-coordinator: signal %d, stopping\n", sig);
    stopping = true;
    reaper.join();
    server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
    status.stop();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera-coordinator: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
