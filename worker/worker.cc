#include "worker/worker.h"

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "core/scene/load.h"
#include "scene_bundle.h"

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

void Worker::release(uint64_t task_id) {
  v1::ReleaseRequest rel;
  rel.set_worker_id(worker_id_);
  rel.set_task_id(task_id);
  v1::ReleaseResponse rr;
  stub_->ReleaseTask(context(2).get(), rel, &rr);
}

std::optional<v1::Task> Worker::fetch_task(grpc::Status* status, uint32_t* retry_ms) {
  v1::GetTaskRequest req;
  req.set_worker_id(worker_id_);
  v1::GetTaskResponse resp;
  *status = stub_->GetTask(context(10).get(), req, &resp);
  *retry_ms = resp.retry_after_ms();
  if (!status->ok() || !resp.has_task()) return std::nullopt;
  return resp.task();
}

bool Worker::submit(const v1::TaskResult& result, const std::atomic<bool>& stop) {
  for (int attempt = 0; attempt < 5 && !stop; ++attempt) {
    v1::ResultAck ack;
    const grpc::Status rs = stub_->SubmitResult(context(30).get(), result, &ack);
    if (rs.ok()) return true;
    if (options_.verbose) std::fprintf(stderr, "tessera-worker: submit: %s\n", rs.error_message().c_str());
    std::this_thread::sleep_for(std::chrono::milliseconds(100 << attempt));
  }
  return false;
}

void Worker::run(const std::atomic<bool>& stop) {
  if (!register_worker(stop)) return;
  // While a tile renders, the next task is fetched and the previous result is sent, so
  // the cores never wait for a round trip to the coordinator.
  std::optional<v1::Task> next;
  std::future<bool> sending;
  while (!stop) {
    std::optional<v1::Task> current = std::move(next);
    next.reset();
    if (!current) {
      grpc::Status st;
      uint32_t retry_ms = 0;
      current = fetch_task(&st, &retry_ms);
      if (!st.ok()) {
        if (options_.verbose) std::fprintf(stderr, "tessera-worker: get task: %s\n", st.error_message().c_str());
        // Unknown worker (the coordinator restarted) or unreachable: register again.
        sleep_backoff(stop);
        if (!register_worker(stop)) break;
        continue;
      }
      backoff_ = 0.1;
      if (!current) {
        const auto until = now_seconds() + std::max(10u, retry_ms) / 1000.0;
        while (!stop && now_seconds() < until) std::this_thread::sleep_for(std::chrono::milliseconds(10));
        continue;
      }
    }
    const v1::Task& task = *current;
    std::atomic<bool> abort{false};
    std::atomic<uint64_t> prefetched{0};
    bool done = false;
    std::mutex mu;
    std::condition_variable cv;
    std::future<std::optional<v1::Task>> prefetch = std::async(std::launch::async, [&]() -> std::optional<v1::Task> {
      grpc::Status st;
      uint32_t retry_ms = 0;
      std::optional<v1::Task> t = fetch_task(&st, &retry_ms);
      if (t) prefetched = t->task_id();
      return t;
    });
    // Heartbeats keep the leases (current and prefetched) while rendering; a "no" for the
    // current task (cancelled, reassigned) or a stop request aborts the render. The
    // thread wakes at once when the render ends.
    std::thread heart([&] {
      std::unique_lock<std::mutex> lock(mu);
      double due = now_seconds() + heartbeat_ms_ / 1000.0;
      while (!done) {
        if (stop) abort = true;
        if (now_seconds() >= due) {
          lock.unlock();
          for (uint64_t id : {task.task_id(), prefetched.load()}) {
            if (!id) continue;
            v1::HeartbeatRequest hb;
            hb.set_worker_id(worker_id_);
            hb.set_task_id(id);
            v1::HeartbeatResponse hr;
            if (stub_->Heartbeat(context(5).get(), hb, &hr).ok() && !hr.keep_going() && id == task.task_id())
              abort = true;
          }
          due = now_seconds() + heartbeat_ms_ / 1000.0;
          lock.lock();
          continue;
        }
        cv.wait_for(lock, std::chrono::milliseconds(10));  // also polls `stop` (set by a signal)
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
    const double seconds = now_seconds() - t0;
    {
      std::lock_guard<std::mutex> lock(mu);
      done = true;
    }
    cv.notify_all();
    heart.join();
    if (!ok) {  // abandoned: give the lease back so another worker starts at once
      release(task.task_id());
      next = prefetch.get();
      if (!stop) sleep_backoff(stop);
      continue;
    }
    auto result = std::make_shared<v1::TaskResult>();
    result->set_worker_id(worker_id_);
    result->set_task_id(task.task_id());
    result->set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
    result->set_sums_zstd(encode_sums(sums));
    result->set_samples(stats.samples);
    result->set_rays(stats.rays.rays + stats.rays.shadow_rays);
    result->set_nan_samples(stats.nan_samples);
    result->set_render_seconds(seconds);
    if (sending.valid() && sending.get()) ++tasks_done_;
    sending = std::async(std::launch::async, [this, result, &stop] { return submit(*result, stop); });
    // Only now wait for the prefetched task: when there is no work left it long-polls,
    // and the result must not wait behind it.
    next = prefetch.get();
  }
  if (sending.valid() && sending.get()) ++tasks_done_;
  if (next) release(next->task_id());
}

}  // namespace tessera
