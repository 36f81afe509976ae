#include "worker/worker.h"

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "core/scene/load.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

std::unique_ptr<grpc::ClientContext> context(double seconds) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000)));
  return ctx;
}

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

Worker::Worker(WorkerOptions options) : options_(std::move(options)) {
  if (options_.threads <= 0) options_.threads = int(std::max(1u, std::thread::hardware_concurrency()));
  if (options_.name.empty()) {
    char host[256] = {};
    gethostname(host, sizeof host - 1);
    options_.name = std::string(host) + ":" + std::to_string(getpid());
  }
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  // Reconnect quickly after the coordinator comes back.
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  channel_ = grpc::CreateCustomChannel(options_.coordinator, grpc::InsecureChannelCredentials(), args);
  stub_ = v1::TesseraWorker::NewStub(channel_);
}

Worker::~Worker() = default;

void Worker::sleep_backoff(const std::atomic<bool>& stop) {
  const auto until = now_seconds() + backoff_;
  while (!stop && now_seconds() < until) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  backoff_ = std::min(5.0, backoff_ * 2);
}

bool Worker::register_worker(const std::atomic<bool>& stop) {
  while (!stop) {
    v1::RegisterRequest req;
    req.set_version(kProtocolVersion);
    req.set_name(options_.name);
    req.set_threads(uint32_t(options_.threads));
    v1::RegisterResponse resp;
    const grpc::Status st = stub_->Register(context(5).get(), req, &resp);
    if (st.ok()) {
      worker_id_ = resp.worker_id();
      heartbeat_ms_ = std::max(50u, resp.heartbeat_interval_ms());
      backoff_ = 0.1;
      if (options_.verbose)
        std::fprintf(stderr, "tessera-worker: registered as %llu\n", (unsigned long long)worker_id_);
      return true;
    }
    if (options_.verbose)
      std::fprintf(stderr, "tessera-worker: coordinator %s: %s; retrying\n", options_.coordinator.c_str(),
                   st.error_message().c_str());
    sleep_backoff(stop);
  }
  return false;
}

const Scene& Worker::scene_for(const std::string& hash) {
  if (auto it = scenes_.find(hash); it != scenes_.end()) return *it->second;
  if (hash.size() != 32 || hash.find_first_not_of("0123456789abcdef") != std::string::npos)
    throw WireError("bad scene hash '" + hash + "'");
  const fs::path dir = fs::path(options_.cache_dir) / hash;
  const fs::path marker = dir / ".main";
  std::string main;
  if (std::ifstream in(marker); in) {
    std::getline(in, main);  // cached on disk by an earlier run
    main = (dir / main).string();
  } else {
    v1::FetchSceneRequest req;
    req.set_scene_hash(hash);
    v1::SceneBundle bundle;
    const grpc::Status st = stub_->FetchScene(context(120).get(), req, &bundle);
    if (!st.ok()) throw std::runtime_error("fetch scene " + hash + ": " + st.error_message());
    if (bundle_hash(bundle.main_file(), bundle.files()) != hash)
      throw WireError("scene bundle does not match its hash");
    main = unpack_bundle(dir.string(), bundle.main_file(), bundle.files());
    std::ofstream(marker) << bundle.main_file() << "\n";
  }
  auto scene = std::make_unique<Scene>(load_scene(main));
  const Scene& ref = *scene;
  scenes_[hash] = std::move(scene);
  return ref;
}

const TileRenderer& Worker::renderer_for(const v1::Task& task) {
  const std::string key = task.scene_hash() + task.settings().SerializeAsString();
  if (renderer_ && key == renderer_key_) return *renderer_;
  renderer_.reset();
  const Scene& scene = scene_for(task.scene_hash());
  renderer_ = std::make_unique<TileRenderer>(scene, from_proto(task.settings()));
  renderer_key_ = key;
  return *renderer_;
}

bool Worker::render(const v1::Task& task, std::vector<PixelSums>* sums, TileStats* stats,
                    const std::atomic<bool>& abort) {
  const TileRenderer& r = renderer_for(task);
  const Rect tile = from_proto(task.tile());
  if (!task.active().empty() && task.active().size() != size_t(tile.area())) throw WireError("active mask size");
  const uint8_t* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
  // Horizontal strips, one per thread; pixels are independent, so the concatenation is
  // exactly the tile rendered in one piece.
  const int n = std::max(1, std::min(options_.threads, tile.h));
  std::vector<std::vector<PixelSums>> parts(static_cast<size_t>(n));
  std::vector<TileStats> part_stats(static_cast<size_t>(n));
  std::vector<std::thread> pool;
  for (int i = 0; i < n; ++i) {
    const int y0 = tile.h * i / n, y1 = tile.h * (i + 1) / n;
    pool.emplace_back([&, i, y0, y1] {
      const Rect strip{tile.x, tile.y + y0, tile.w, y1 - y0};
      parts[size_t(i)] = r.render(strip, task.sample_begin(), task.sample_end(),
                                  mask ? mask + size_t(y0) * tile.w : nullptr, &part_stats[size_t(i)], &abort);
    });
  }
  for (std::thread& t : pool) t.join();
  if (abort) return false;
  sums->clear();
  for (int i = 0; i < n; ++i) {
    sums->insert(sums->end(), parts[size_t(i)].begin(), parts[size_t(i)].end());
    stats->add(part_stats[size_t(i)]);
  }
  return true;
}

void Worker::run(const std::atomic<bool>& stop) {
  if (!register_worker(stop)) return;
  while (!stop) {
    v1::GetTaskRequest req;
    req.set_worker_id(worker_id_);
    v1::GetTaskResponse resp;
    const grpc::Status st = stub_->GetTask(context(10).get(), req, &resp);
    if (!st.ok()) {
      if (options_.verbose) std::fprintf(stderr, "tessera-worker: get task: %s\n", st.error_message().c_str());
      // Unknown worker (the coordinator restarted) or unreachable: register again.
      sleep_backoff(stop);
      if (!register_worker(stop)) return;
      continue;
    }
    backoff_ = 0.1;
    if (!resp.has_task()) {
      const auto until = now_seconds() + std::max(10u, resp.retry_after_ms()) / 1000.0;
      while (!stop && now_seconds() < until) std::this_thread::sleep_for(std::chrono::milliseconds(10));
      continue;
    }
    const v1::Task& task = resp.task();
    std::atomic<bool> abort{false}, done{false};
    // Heartbeats keep the lease while rendering; a "no" (cancelled, reassigned) or a stop
    // request aborts the render.
    std::thread heart([&] {
      double next = now_seconds() + heartbeat_ms_ / 1000.0;
      while (!done) {
        if (stop) abort = true;
        if (now_seconds() >= next) {
          v1::HeartbeatRequest hb;
          hb.set_worker_id(worker_id_);
          hb.set_task_id(task.task_id());
          v1::HeartbeatResponse hr;
          if (stub_->Heartbeat(context(5).get(), hb, &hr).ok() && !hr.keep_going()) abort = true;
          next = now_seconds() + heartbeat_ms_ / 1000.0;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
      }
    });
    std::vector<PixelSums> sums;
    TileStats stats;
    bool ok = false;
    const double t0 = now_seconds();
    try {
      ok = render(task, &sums, &stats, abort);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera-worker: task %llu: %s\n", (unsigned long long)task.task_id(), e.what());
    }
    done = true;
    heart.join();
    if (!ok) {  // abandoned: give the lease back so another worker starts at once
      v1::ReleaseRequest rel;
      rel.set_worker_id(worker_id_);
      rel.set_task_id(task.task_id());
      v1::ReleaseResponse rr;
      stub_->ReleaseTask(context(2).get(), rel, &rr);
      if (!stop) sleep_backoff(stop);
      continue;
    }
    v1::TaskResult result;
    result.set_worker_id(worker_id_);
    result.set_task_id(task.task_id());
    result.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
    result.set_sums_zstd(encode_sums(sums));
    result.set_samples(stats.samples);
    result.set_rays(stats.rays.rays + stats.rays.shadow_rays);
    result.set_nan_samples(stats.nan_samples);
    result.set_render_seconds(now_seconds() - t0);
    for (int attempt = 0; attempt < 5 && !stop; ++attempt) {
      v1::ResultAck ack;
      const grpc::Status rs = stub_->SubmitResult(context(30).get(), result, &ack);
      if (rs.ok()) {
        ++tasks_done_;
        break;
      }
      if (options_.verbose) std::fprintf(stderr, "tessera-worker: submit: %s\n", rs.error_message().c_str());
      sleep_backoff(stop);
    }
  }
}

}  // namespace tessera
