#include "worker/worker.h"

#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <thread>

#include "core/scene/load.h"
#include "core/util/thread_pool.h"
#include "scene_bundle.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

constexpr int kLingerMs = 50;  // how long finished results may wait for company
// How often the lease keeper and the fetcher look at the stop flag (set by a signal): each
// look wakes a thread, which on a small machine takes a core from a render thread.
constexpr int kStopPollMs = 100;

std::unique_ptr<grpc::ClientContext> context(const Access& access, double seconds) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  authorize(*ctx, access);
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000)));
  return ctx;
}

double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

}  // namespace

struct Worker::Prepared {
  std::shared_ptr<Scene> scene;  // outlives the renderer, which refers to it
  std::unique_ptr<TileRenderer> renderer;
  std::string base_key;  // scene and settings but the frame: renderers sharing one BVH
};

struct Worker::Held {
  v1::Task task;
  std::shared_ptr<const Prepared> prepared;
  Rect rect;
  const uint8_t* mask = nullptr;  // into task.active; null: every pixel
  int next_row = 0, rows_done = 0;
  std::vector<PixelSums> sums;
  TileStats stats;
  std::atomic<bool> cancel{false};
  double first_row = 0, last_row = 0;  // steady seconds
  double busy = 0;                     // thread-seconds spent on it
  double row_samples(int row) const {  // for queue sizing
    const uint32_t n = task.sample_end() - task.sample_begin();
    if (!mask) return double(rect.w) * n;
    int active = 0;
    for (int x = 0; x < rect.w; ++x) active += mask[size_t(row) * rect.w + x] != 0;
    return double(active) * n;
  }
};

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
  channel_ = grpc::CreateCustomChannel(options_.coordinator, channel_credentials(options_.access), args);
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
    // A coordinator that cannot be reached has no work for us either.
    if (options_.exit_when_idle_seconds > 0 && now_seconds() - last_work_ > options_.exit_when_idle_seconds) {
      std::fprintf(stderr, "tessera-worker: no work for %g s (--exit-when-idle; coordinator %s unreachable): leaving\n",
                   options_.exit_when_idle_seconds, options_.coordinator.c_str());
      return false;
    }
    v1::RegisterRequest req;
    req.set_version(kProtocolVersion);
    req.set_name(options_.name);
    req.set_threads(uint32_t(options_.threads));
    v1::RegisterResponse resp;
    const grpc::Status st = stub_->Register(context(options_.access, 5).get(), req, &resp);
    if (st.ok()) {
      worker_id_ = resp.worker_id();
      heartbeat_ms_ = std::max(50u, resp.heartbeat_interval_ms());
      backoff_ = 0.1;
      if (options_.verbose)
        std::fprintf(stderr, "tessera-worker: registered as %llu\n", (unsigned long long)worker_id_.load());
      return true;
    }
    if (st.error_code() == grpc::StatusCode::UNAUTHENTICATED ||
        st.error_code() == grpc::StatusCode::PERMISSION_DENIED ||
        st.error_code() == grpc::StatusCode::INVALID_ARGUMENT) {  // retrying cannot help
      std::fprintf(stderr, "tessera-worker: error: coordinator %s refused to register this worker: %s\n",
                   options_.coordinator.c_str(), st.error_message().c_str());
      refused_ = true;
      return false;
    }
    if (options_.verbose)
      std::fprintf(stderr, "tessera-worker: coordinator %s: %s; retrying\n", options_.coordinator.c_str(),
                   st.error_message().c_str());
    sleep_backoff(stop);
  }
  return false;
}

std::shared_ptr<Scene> Worker::scene_for(const std::string& hash) {
  if (auto it = scenes_.find(hash); it != scenes_.end()) return it->second;
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
    const grpc::Status st = stub_->FetchScene(context(options_.access, 120).get(), req, &bundle);
    if (!st.ok()) throw std::runtime_error("fetch scene " + hash + ": " + st.error_message());
    if (bundle_hash(bundle.main_file(), bundle.files()) != hash)
      throw WireError("scene bundle does not match its hash");
    main = unpack_bundle(dir.string(), bundle.main_file(), bundle.files());
    std::ofstream(marker) << bundle.main_file() << "\n";
  }
  return scenes_[hash] = std::make_shared<Scene>(load_scene(main));
}

std::shared_ptr<const Worker::Prepared> Worker::prepare(const v1::Task& task) {
  const std::string key = task.scene_hash() + task.settings().SerializeAsString();
  if (auto it = prepared_.find(key); it != prepared_.end()) return it->second;
  auto p = std::make_shared<Prepared>();
  const RenderSettings settings = from_proto(task.settings());
  // The frames of a sequence share one acceleration structure: a renderer built for any
  // frame of the same (scene, settings) lends its own to the next frame's.
  v1::RenderSettings base = task.settings();
  base.clear_frame();
  const std::string base_key = task.scene_hash() + base.SerializeAsString();
  std::shared_ptr<const Prepared> sibling;
  for (const auto& [k, q] : prepared_)
    if (q->base_key == base_key) sibling = q;
  if (sibling) {
    p->scene = sibling->scene;
    p->renderer = std::make_unique<TileRenderer>(*sibling->renderer, settings);
  } else {
    p->scene = scene_for(task.scene_hash());
    p->renderer = std::make_unique<TileRenderer>(*p->scene, settings);
  }
  p->base_key = base_key;
  // A few renderers stay built (jobs alternate by priority, frames follow each other);
  // tasks in flight hold theirs.
  prepared_[key] = p;
  prepared_order_.push_back(key);
  if (prepared_order_.size() > 8) {
    prepared_.erase(prepared_order_.front());
    prepared_order_.pop_front();
  }
  return p;
}

bool Worker::wants_more_locked() const {
  if (held_.size() >= size_t(options_.max_tasks)) return false;
  if (queued_rows_ < 2 * uint64_t(options_.threads)) return true;  // threads about to run dry
  // Refill at half the lookahead, up to all of it: fewer, larger requests.
  const double rate = samples_per_thread_second_ * options_.threads;
  return rate > 0 && queued_samples_ < 0.5 * rate * options_.lookahead_seconds;
}

void Worker::render_loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    work_.wait(lock, [this] { return stopping_ || !queue_.empty(); });
    if (stopping_) return;
    const std::shared_ptr<Held> h = queue_.front();
    const int row = h->next_row++;
    if (h->next_row == h->rect.h) {
      queue_.pop_front();
      if (queue_.empty() && !outbox_.empty()) outbox_cv_.notify_one();  // results stop lingering
    }
    --queued_rows_;
    queued_samples_ -= h->row_samples(row);
    // Wake the fetcher only when it has something to do: a wake-up per row cost a 2-core
    // machine 4% of its render time in context switches.
    if (wants_more_locked()) more_.notify_one();
    lock.unlock();
    const double t0 = now_seconds();
    TileStats stats;
    const Rect r{h->rect.x, h->rect.y + row, h->rect.w, 1};
    const std::vector<PixelSums> sums =
        h->prepared->renderer->render(r, h->task.sample_begin(), h->task.sample_end(),
                                      h->mask ? h->mask + size_t(row) * h->rect.w : nullptr, &stats, &h->cancel);
    const double t1 = now_seconds();
    lock.lock();
    busy_thread_seconds_ += t1 - t0;
    h->busy += t1 - t0;
    h->first_row = h->rows_done == 0 ? t0 : std::min(h->first_row, t0);
    h->last_row = std::max(h->last_row, t1);
    std::copy(sums.begin(), sums.end(), h->sums.begin() + ptrdiff_t(row) * h->rect.w);
    h->stats.add(stats);
    if (++h->rows_done == h->rect.h && !h->cancel) {
      if (h->busy > 0) {
        const double rate = double(h->stats.samples) / h->busy;
        samples_per_thread_second_ =
            samples_per_thread_second_ > 0 ? 0.7 * samples_per_thread_second_ + 0.3 * rate : rate;
      }
      // The sender sleeps through its linger: only the first result of a batch wakes it.
      if (outbox_.empty()) outbox_cv_.notify_one();
      outbox_.push_back(h);
    }
  }
}

void Worker::send_loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    outbox_cv_.wait(lock, [this] { return stopping_ || !outbox_.empty(); });
    if (outbox_.empty()) return;  // stopping, and everything finished was sent
    // While the render threads still have work, let results gather for a moment: one call
    // for several results. With nothing queued, a result may be what frees the next pass
    // of a tile, so it goes at once.
    // (The render thread that takes the last queued row wakes it early.)
    const auto linger_until = std::chrono::steady_clock::now() + std::chrono::milliseconds(kLingerMs);
    outbox_cv_.wait_until(lock, linger_until, [this] { return stopping_ || queue_.empty(); });
    // Everything finished so far goes in one request.
    const std::deque<std::shared_ptr<Held>> batch = std::move(outbox_);
    outbox_.clear();
    const double busy = busy_thread_seconds_, threads = options_.threads * (now_seconds() - registered_at_);
    lock.unlock();
    v1::ResultBatch results;
    for (const std::shared_ptr<Held>& h : batch) {
      v1::TaskResult* r = results.add_results();
      r->set_worker_id(worker_id_);
      r->set_task_id(h->task.task_id());
      r->set_raw_size(uint32_t(h->sums.size() * kBytesPerPixel));
      if (options_.lie)
        for (PixelSums& p : h->sums) p = PixelSums{p.r * 0.8, p.g * 0.8, p.b * 0.8, p.lum2 * 0.64, p.n};
      r->set_sums_zstd(encode_sums(h->sums));
      r->set_samples(h->stats.samples);
      r->set_rays(h->stats.rays.rays + h->stats.rays.shadow_rays);
      r->set_nan_samples(h->stats.nan_samples);
      r->set_render_seconds(h->last_row - h->first_row);
      r->set_busy_thread_seconds(busy);
      r->set_thread_seconds(threads);
    }
    bool sent = false;
    for (int attempt = 0; attempt < 5 && !sent; ++attempt) {
      v1::ResultAcks acks;
      const grpc::Status st = stub_->SubmitResults(context(options_.access, 30).get(), results, &acks);
      sent = st.ok();
      if (!sent) {
        if (options_.verbose) std::fprintf(stderr, "tessera-worker: submit: %s\n", st.error_message().c_str());
        std::this_thread::sleep_for(std::chrono::milliseconds(100 << attempt));
      }
    }
    lock.lock();
    for (const std::shared_ptr<Held>& h : batch) {
      if (sent) ++tasks_done_;
      held_.erase(h->task.task_id());  // unsent: its lease expires and another worker renders it
    }
    more_.notify_one();
  }
}

void Worker::drop_locked(uint64_t task_id) {
  auto it = held_.find(task_id);
  if (it == held_.end()) return;
  const std::shared_ptr<Held> h = it->second;
  h->cancel = true;
  for (auto q = queue_.begin(); q != queue_.end(); ++q)
    if (*q == h) {
      for (int row = h->next_row; row < h->rect.h; ++row) {
        --queued_rows_;
        queued_samples_ -= h->row_samples(row);
      }
      queue_.erase(q);
      break;
    }
  held_.erase(it);
  more_.notify_one();
}

void Worker::keep_leases(const std::atomic<bool>& stop) {
  std::unique_lock<std::mutex> lock(mu_);
  double due = now_seconds() + heartbeat_ms_ / 1000.0;
  while (!stopping_) {
    if (stop) {  // a signal: abandon unfinished work at once (renders check per pixel)
      stopping_ = true;
      for (auto& [id, h] : held_) h->cancel = true;
      work_.notify_all();
      more_.notify_all();
      outbox_cv_.notify_all();
      return;
    }
    if (now_seconds() >= due) {
      v1::HeartbeatRequest hb;
      hb.set_worker_id(worker_id_);
      for (const auto& [id, h] : held_) hb.add_task_ids(id);
      lock.unlock();
      v1::HeartbeatResponse hr;
      const bool ok = hb.task_ids_size() == 0 || stub_->Heartbeat(context(options_.access, 5).get(), hb, &hr).ok();
      lock.lock();
      if (ok)
        for (uint64_t id : hr.refused())
          if (auto it = held_.find(id); it != held_.end() && it->second->rows_done < it->second->rect.h)
            drop_locked(id);
      due = now_seconds() + heartbeat_ms_ / 1000.0;
    }
    // Until the next heartbeat, looking at `stop` (set by a signal) now and then.
    stopped_cv_.wait_for(lock, std::chrono::milliseconds(std::clamp(int64_t((due - now_seconds()) * 1000) + 1,
                                                                    int64_t(1), int64_t(kStopPollMs))));
  }
}

void Worker::release(uint64_t task_id, const std::string& error) {
  v1::ReleaseRequest rel;
  rel.set_worker_id(worker_id_);
  rel.set_task_id(task_id);
  rel.set_error(error);
  v1::ReleaseResponse rr;
  stub_->ReleaseTask(context(options_.access, 2).get(), rel, &rr);
}

void Worker::enqueue(const v1::Task& task, const std::atomic<bool>& stop) {
  auto h = std::make_shared<Held>();
  h->task = task;
  try {
    h->rect = from_proto(h->task.tile());
    if (!h->task.active().empty() && h->task.active().size() != size_t(h->rect.area()))
      throw WireError("active mask size");
    if (h->rect.area() <= 0) throw WireError("empty tile");
    h->prepared = prepare(h->task);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera-worker: task %llu: %s\n", (unsigned long long)h->task.task_id(), e.what());
    release(h->task.task_id(), e.what());  // another worker may manage; this one backs off
    sleep_backoff(stop);
    return;
  }
  if (!h->task.active().empty()) h->mask = reinterpret_cast<const uint8_t*>(h->task.active().data());
  h->sums.resize(size_t(h->rect.area()));
  std::lock_guard<std::mutex> lock(mu_);
  held_[h->task.task_id()] = h;
  queue_.push_back(h);
  queued_rows_ += uint64_t(h->rect.h);
  for (int row = 0; row < h->rect.h; ++row) queued_samples_ += h->row_samples(row);
  work_.notify_all();
}

bool Worker::run(const std::atomic<bool>& stop) {
  last_work_ = now_seconds();
  if (!register_worker(stop)) return !refused_;
  registered_at_ = now_seconds();
  stopping_ = false;
  std::thread keeper([&] {
    set_thread_name("leases");
    keep_leases(stop);
  });
  std::thread sender([this] {
    set_thread_name("send");
    send_loop();
  });
  {
    ThreadPool pool(options_.threads);
    for (int i = 0; i < pool.size(); ++i) pool.run([this] { render_loop(); });
    while (!stop) {
      if (options_.exit_when_idle_seconds > 0) {
        std::lock_guard<std::mutex> lock(mu_);
        if (!held_.empty()) {
          last_work_ = now_seconds();
        } else if (now_seconds() - last_work_ > options_.exit_when_idle_seconds) {
          std::fprintf(stderr, "tessera-worker: no work for %g s (--exit-when-idle): leaving\n",
                       options_.exit_when_idle_seconds);
          break;
        }
      }
      v1::GetTaskRequest req;
      req.set_worker_id(worker_id_);
      {
        std::unique_lock<std::mutex> lock(mu_);
        more_.wait_for(lock, std::chrono::milliseconds(kStopPollMs), [&] { return stopping_ || wants_more_locked(); });
        if (stopping_ || !wants_more_locked()) continue;
        // As much work as the threads get through in the lookahead, at the measured speed;
        // two tasks until there is a measurement.
        const double rate = samples_per_thread_second_ * options_.threads;
        const uint32_t room = uint32_t(options_.max_tasks - int(held_.size()));
        req.set_max_tasks(rate > 0 ? room : std::min(room, 2u));
        if (rate > 0) req.set_max_samples(uint64_t(std::max(1.0, rate * options_.lookahead_seconds - queued_samples_)));
      }
      v1::GetTaskResponse resp;
      const grpc::Status st =
          stub_->GetTask(context(options_.access, 10).get(), req, &resp);  // long-polls when there is no work
      if (!st.ok()) {
        if (options_.verbose) std::fprintf(stderr, "tessera-worker: get task: %s\n", st.error_message().c_str());
        // Unknown worker (the coordinator restarted) or unreachable: its leases are gone.
        {
          std::lock_guard<std::mutex> lock(mu_);
          while (!held_.empty()) drop_locked(held_.begin()->first);
        }
        sleep_backoff(stop);
        if (!register_worker(stop)) break;  // stopped, or refused
        continue;
      }
      backoff_ = 0.1;
      if (resp.tasks_size() > 0) last_work_ = now_seconds();
      for (const v1::Task& task : resp.tasks()) enqueue(task, stop);
    }
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
    for (auto& [id, h] : held_) h->cancel = true;
    work_.notify_all();
    outbox_cv_.notify_all();
    stopped_cv_.notify_all();
  }  // joins the render threads
  keeper.join();
  sender.join();  // finished results are sent first
  // What was not finished goes back, so another worker starts on it at once, and this
  // worker stops counting as one.
  v1::UnregisterRequest bye;
  bye.set_worker_id(worker_id_);
  v1::UnregisterResponse ok;
  if (!stub_->Unregister(context(options_.access, 2).get(), bye, &ok).ok())
    for (const auto& [id, h] : held_) release(id);  // at least the leases, one by one
  held_.clear();
  queue_.clear();
  return !refused_;
}

}  // namespace tessera
