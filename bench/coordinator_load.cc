// Coordinator load test: one coordinator (real gRPC and HTTP servers on 127.0.0.1) and
// many simulated workers that return ready-made tile buffers instantly, so only the
// coordinator's own cost is measured: merged tiles per second, and the status endpoint's
// latency while it is under that load.
//
// Usage: tessera_coordinator_load SCENE [--workers N] [--threads N] [--batch N] [--seconds S]
//                                 [--size W H] [--jobs N] [--json FILE]
//                                 [--checkpoint-seconds S] [--verify-fraction F]
#include <grpcpp/grpcpp.h>
#include <httplib.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>
#include <utility>

#include "server/grpc_services.h"
#include "server/status_http.h"

using namespace tessera;
namespace fs = std::filesystem;

namespace {
double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
double cpu_seconds(int who) {  // RUSAGE_SELF: the process; RUSAGE_THREAD: the caller
  rusage u{};
  getrusage(who, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(p * double(v.size())))];
}
}  // namespace

const char* kUsage =
    "usage: tessera_coordinator_load SCENE [--workers N] [--threads N] [--batch N] [--seconds S] [--size W H]\n"
    "                                [--jobs N] [--json FILE] [--checkpoint-seconds S] [--verify-fraction F]\n"
    "  SCENE        any scene file (.dae, .gltf); only its upload and check are exercised\n"
    "  --workers N  simulated workers (default 1000)\n"
    "  --threads N  client threads driving them (default 8)\n"
    "  --batch N    tasks a simulated worker asks for and returns at once (default 8)\n"
    "  --seconds S  measuring time after 1 s of warm-up (default 10)\n"
    "  --size W H   frame size, in 32-pixel tiles of 1-sample passes (default 1920 1080)\n"
    "  --jobs N     frames queued at once (default 4). Each worker gets at most its share of\n"
    "               the outstanding tasks, so one frame of 2,040 tiles gives 1,000 workers\n"
    "               batches of 3 whatever they ask for\n"
    "  --json FILE  also write the figures as JSON\n"
    "  --checkpoint-seconds S, --verify-fraction F\n"
    "               the coordinator's settings (defaults: the coordinator's, 5 and 0.01)\n";

int main(int argc, char** argv) {
  int workers = 1000, threads = 8, width = 1920, height = 1080, batch = 8, jobs = 4;
  double seconds = 10;
  CoordinatorOptions opt;
  std::string json_path, scene;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto number = [&](const char* flag) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "tessera_coordinator_load: %s needs a value\n%s", flag, kUsage);
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      return 0;
    } else if (a == "--workers") {
      workers = std::atoi(number("--workers"));
    } else if (a == "--threads") {
      threads = std::atoi(number("--threads"));
    } else if (a == "--batch") {
      batch = std::atoi(number("--batch"));
    } else if (a == "--seconds") {
      seconds = std::atof(number("--seconds"));
    } else if (a == "--jobs") {
      jobs = std::atoi(number("--jobs"));
    } else if (a == "--checkpoint-seconds") {
      opt.checkpoint_seconds = std::atof(number("--checkpoint-seconds"));
    } else if (a == "--verify-fraction") {
      opt.verify_fraction = std::atof(number("--verify-fraction"));
    } else if (a == "--json") {
      json_path = number("--json");
    } else if (a == "--size") {
      width = std::atoi(number("--size"));
      height = std::atoi(number("--size"));
    } else if (a[0] != '-' && scene.empty()) {
      scene = a;
    } else {
      std::fprintf(stderr, "tessera_coordinator_load: unknown argument '%s'\n%s", a.c_str(), kUsage);
      return 2;
    }
  }
  if (scene.empty() || workers < 1 || threads < 1 || batch < 1 || jobs < 1 || !(seconds > 0) || width < 1 ||
      height < 1) {
    std::fprintf(stderr, "%s", kUsage);
    return 2;
  }
  const fs::path data = fs::temp_directory_path() / ("tessera_load_" + std::to_string(getpid()));
  opt.data_dir = data.string();
  opt.lease_seconds = 60;
  Coordinator c(opt);
  ClientService client(c);
  WorkerService worker_service(c);
  grpc::ServerBuilder b;
  int port = 0;
  b.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
  configure_server(b);
  b.RegisterService(&client);
  b.RegisterService(&worker_service);
  auto server = b.BuildAndStart();
  StatusHttp http(c);
  const int http_port = http.bind("127.0.0.1", 0);
  http.start();

  // A 1920 x 1080 frame (by default) in 32-pixel tiles, passes of 1 sample.
  RenderSettings s;
  s.camera.width = width;
  s.camera.height = height;
  s.spp = 1000;
  s.pass_spp = 1;
  // The simulated results carry sums only: no light paths (a scene with mirror or glass
  // would otherwise be decided `on`, and its results must carry splats).
  s.light_tracer = RenderSettings::LightTracer::kOff;
  v1::SubmitJobRequest req;
  req.set_version(kProtocolVersion);
  std::string main;
  pack_scene(scene, &main, req.mutable_files());
  req.set_main_file(main);
  *req.mutable_settings() = to_proto(s);
  for (int j = 0; j < jobs; ++j) c.submit(req);
  // A tile's sums, one sample a pixel as a render gives it, made once per tile size (the
  // last row and column of tiles are cut short when the size does not divide by 32).
  auto payload_for = [](size_t pixels) {
    std::vector<PixelSums> sums(pixels);
    for (size_t i = 0; i < sums.size(); ++i) {
      sums[i] = PixelSums{0.1 * (i % 7), 0.2, 0.3, 0, 1};
      sums[i].lum2 = sums[i].lum_sum() * sums[i].lum_sum();
    }
    return encode_sums(sums);
  };

  std::atomic<bool> stop{false};
  std::atomic<uint64_t> merged{0}, rpcs{0};
  std::vector<std::atomic<double>> load_cpu(size_t(threads) + 1);  // clients, then the poller
  std::vector<std::thread> pool;
  const std::string target = "127.0.0.1:" + std::to_string(port);
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([&, t] {
      auto stub = v1::TesseraWorker::NewStub(grpc::CreateChannel(target, grpc::InsecureChannelCredentials()));
      std::vector<std::pair<uint64_t, std::string>> ids;  // this thread's share of the simulated workers
      std::map<size_t, std::string> payloads;             // by tile area
      for (int w = t; w < workers; w += threads) {
        grpc::ClientContext ctx;
        v1::RegisterRequest r;
        r.set_version(kProtocolVersion);
        r.set_name("sim" + std::to_string(w));
        v1::RegisterResponse resp;
        if (stub->Register(&ctx, r, &resp).ok()) ids.emplace_back(resp.worker_id(), resp.worker_secret());
      }
      if (ids.empty()) return;  // more client threads than workers
      for (size_t k = 0; !stop; k = (k + 1) % ids.size()) {
        load_cpu[size_t(t)] = cpu_seconds(RUSAGE_THREAD);
        grpc::ClientContext c1;
        v1::GetTaskRequest g;
        g.set_worker_id(ids[k].first);
        g.set_worker_secret(ids[k].second);
        g.set_max_tasks(uint32_t(batch));
        v1::GetTaskResponse tasks;
        if (!stub->GetTask(&c1, g, &tasks).ok() || tasks.tasks_size() == 0) continue;
        grpc::ClientContext c2;
        v1::ResultBatch results;
        results.set_worker_id(ids[k].first);
        results.set_worker_secret(ids[k].second);
        for (const v1::Task& task : tasks.tasks()) {
          v1::TaskResult* res = results.add_results();
          res->set_worker_id(ids[k].first);
          res->set_task_id(task.task_id());
          const Rect tile = from_proto(task.tile());
          std::string& payload = payloads[size_t(tile.area())];
          if (payload.empty()) payload = payload_for(size_t(tile.area()));
          res->set_raw_size(uint32_t(tile.area() * kBytesPerPixel));
          res->set_sums_zstd(payload);
          res->set_samples(1024);
          res->set_render_seconds(0.05);
        }
        v1::ResultAcks acks;
        if (stub->SubmitResults(&c2, results, &acks).ok())
          for (const v1::ResultAck& ack : acks.acks()) merged += ack.accepted();
        rpcs += 2;
      }
    });
  }
  // Status endpoint latency while loaded.
  std::vector<double> status_ms, metrics_ms;
  std::thread poller([&] {
    httplib::Client cli("127.0.0.1", http_port);
    while (!stop) {
      load_cpu[size_t(threads)] = cpu_seconds(RUSAGE_THREAD);
      double t0 = now();
      if (cli.Get("/api/status")) status_ms.push_back((now() - t0) * 1e3);
      t0 = now();
      if (cli.Get("/metrics")) metrics_ms.push_back((now() - t0) * 1e3);
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  std::this_thread::sleep_for(std::chrono::seconds(1));  // registration and warm-up
  const uint64_t m0 = merged, r0 = rpcs;
  // The coordinator's own CPU: the process's, less the simulated workers' and the status
  // poller's threads (each keeps its own CPU time in a slot).
  auto coordinator_cpu = [&] {
    double others = 0;
    for (const auto& c : load_cpu) others += c;
    return cpu_seconds(RUSAGE_SELF) - others;
  };
  const double cpu0 = coordinator_cpu();
  status_ms.clear();
  metrics_ms.clear();
  const double t0 = now();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const double elapsed = now() - t0;
  const uint64_t m1 = merged, r1 = rpcs;
  const double server_cpu = coordinator_cpu() - cpu0;
  const std::vector<double> st = status_ms, mt = metrics_ms;
  stop = true;
  for (auto& t : pool) t.join();
  poller.join();
  http.stop();
  server->Shutdown();
  fs::remove_all(data);

  if (m1 == m0) {  // a coordinator that refuses every result measures nothing
    std::fprintf(stderr, "tessera_coordinator_load: error: no result was merged\n");
    return 1;
  }
  const double tiles_per_s = double(m1 - m0) / elapsed;
  std::printf("checkpoints every %g s, verify fraction %g: %llu checkpoints, %llu checks passed of %llu\n",
              opt.checkpoint_seconds, opt.verify_fraction, (unsigned long long)c.counters().checkpoints_written,
              (unsigned long long)c.counters().checks_passed, (unsigned long long)c.counters().checks_issued);
  std::printf("%d frames %dx%d, simulated workers %d (client threads %d, batches of %d), %.1f s\n", jobs, width, height,
              workers, threads, batch, elapsed);
  std::printf("merged tiles/s %.0f  (32x32 tiles: %.1f M pixel-samples/s merged), worker RPCs/s %.0f\n", tiles_per_s,
              tiles_per_s * 1024 / 1e6, double(r1 - r0) / elapsed);
  const double per_cpu_second = server_cpu > 0 ? double(m1 - m0) / server_cpu : 0;
  std::printf("coordinator: %.2f CPU-s, %.1f us a merged result: %.0f merged results per CPU-second\n", server_cpu,
              1e6 / std::max(1.0, per_cpu_second), per_cpu_second);
  std::printf("status /api/status latency ms: p50 %.2f p99 %.2f max %.2f (%zu requests)\n", percentile(st, 0.5),
              percentile(st, 0.99), percentile(st, 1.0), st.size());
  std::printf("status /metrics    latency ms: p50 %.2f p99 %.2f max %.2f\n", percentile(mt, 0.5), percentile(mt, 0.99),
              percentile(mt, 1.0));
  if (!json_path.empty())
    std::ofstream(json_path) << nlohmann::json{{"workers", workers},
                                               {"batch", batch},
                                               {"jobs", jobs},
                                               {"width", width},
                                               {"height", height},
                                               {"merged_tiles_per_second", tiles_per_s},
                                               {"worker_rpcs_per_second", double(r1 - r0) / elapsed},
                                               {"coordinator_cpu_seconds", server_cpu},
                                               {"merged_per_coordinator_cpu_second", per_cpu_second},
                                               {"status_p50_ms", percentile(st, 0.5)},
                                               {"status_p99_ms", percentile(st, 0.99)},
                                               {"metrics_p50_ms", percentile(mt, 0.5)},
                                               {"metrics_p99_ms", percentile(mt, 0.99)}}
                                    .dump(2)
                             << "\n";
  return 0;
}
