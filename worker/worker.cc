#include "worker/worker.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <thread>

#include "wire.h"
#include "worker/clock.h"
#include "worker/fetcher.h"
#include "worker/lease_keeper.h"
#include "worker/link.h"
#include "worker/render_pool.h"
#include "worker/sender.h"
#include "worker/task_queue.h"

namespace tessera {

using worker::Fetcher;
using worker::LeaseKeeper;
using worker::Link;
using worker::Lookahead;
using worker::now_seconds;
using worker::RenderPool;
using worker::Sender;
using worker::TaskQueue;

namespace {

constexpr int kMaxReconnectBackoffMs = 2000;  // reconnect quickly after the coordinator comes back

std::string host_name() {
  char host[256] = {};
  gethostname(host, sizeof host - 1);
  return host;
}

WorkerOptions resolved(WorkerOptions o) {
  if (o.threads <= 0) o.threads = int(std::max(1u, std::thread::hardware_concurrency()));
  if (o.name.empty()) {  // host:pid, or in a Slurm job host:slurm-JOB (the same across its restarts)
    const std::string host = host_name();
    const char* job = std::getenv("SLURM_JOB_ID");
    const char* task = std::getenv("SLURM_PROCID");
    o.name =
        host + ":" +
        (job && *job ? "slurm-" + std::string(job) + (task && std::string(task) != "0" ? "." + std::string(task) : "")
                     : std::to_string(getpid()));
  }
  return o;
}

}  // namespace

Worker::Worker(WorkerOptions options)
    : Worker(options, v1::TesseraWorker::NewStub(
                          coordinator_channel(options.coordinator, options.access, kMaxReconnectBackoffMs))) {}

Worker::Worker(WorkerOptions options, std::shared_ptr<v1::TesseraWorker::StubInterface> stub)
    : options_(resolved(std::move(options))),
      link_(std::make_unique<Link>(std::move(stub), options_.access)),
      queue_(std::make_unique<TaskQueue>(Lookahead{options_.threads, options_.lookahead_seconds},
                                         uint32_t(options_.passes_per_task))),
      fetcher_(std::make_unique<Fetcher>(
          *link_, *queue_, options_.cache_dir, backoff_,
          worker::SceneCacheBounds{uint64_t(options_.cache_max_gib * double(uint64_t(1) << 30)), 3600,
                                   uint64_t(options_.max_memory_gib * double(uint64_t(1) << 30))})) {}

Worker::~Worker() = default;

uint64_t Worker::tasks_done() const { return queue_->tasks_done(); }

grpc::Status Worker::enrol() {
  v1::EnrolRequest req;
  req.set_name(options_.name);
  v1::EnrolResponse resp;
  const grpc::Status st =
      link_->stub->Enrol(call_context(Access{options_.enrol_token, options_.access.tls_ca_pem}, 5).get(), req, &resp);
  if (st.ok()) {
    link_->set_token(resp.credential());
    enrolled_ = true;
    spdlog::info("enrolled as '{}'", options_.name);
  }
  return st;
}

bool Worker::register_worker(const std::atomic<bool>& stop) {
  bool fresh = false;  // the credential was made in this call: a refusal of it is final
  while (!stop) {
    // A coordinator that cannot be reached has no work for us either.
    if (options_.exit_when_idle_seconds > 0 && now_seconds() - last_work_ > options_.exit_when_idle_seconds) {
      spdlog::info("no work for {:g} s (--exit-when-idle-seconds; coordinator {} unreachable): leaving",
                   options_.exit_when_idle_seconds, options_.coordinator);
      return false;
    }
    grpc::Status st;
    if (!options_.enrol_token.empty() && !enrolled_) {
      st = enrol();
      fresh = st.ok();
    }
    if (st.ok()) {
      v1::RegisterRequest req;
      req.set_version(kProtocolVersion);
      req.set_name(options_.name);
      req.set_threads(uint32_t(options_.threads));
      req.set_host(host_name());
      v1::RegisterResponse resp;
      st = link_->stub->Register(link_->context(5).get(), req, &resp);
      if (st.ok()) {
        link_->set_identity({resp.worker_id(), resp.worker_secret()});
        link_->heartbeat_ms = std::max(50u, resp.heartbeat_interval_ms());
        if (resp.lease_ms() > 0) link_->lease_ms = resp.lease_ms();
        last_contact_ = now_seconds();
        queue_->set_max_leases(resp.max_leases() > 0 ? resp.max_leases() : worker::kDefaultMaxLeases,
                               size_t(options_.max_tasks));
        backoff_.reset();
        if (unreachable_said_ != 0)
          spdlog::info("coordinator {} reached after {:.0f} s", options_.coordinator,
                       now_seconds() - unreachable_since_);
        unreachable_since_ = unreachable_said_ = 0;
        spdlog::debug("registered as {}", resp.worker_id());
        return true;
      }
      // A credential the coordinator no longer knows (unused for an hour, or its name
      // enrolled again): enrol again, once.
      if (enrolled_ && !fresh && st.error_code() == grpc::StatusCode::UNAUTHENTICATED) {
        enrolled_ = false;
        continue;
      }
    }
    if (refused(st)) {
      spdlog::error("coordinator {} refused to register this worker: {}", options_.coordinator, st.error_message());
      refused_ = true;
      return false;
    }
    const std::string hint = tls_hint(st, !options_.access.tls_ca_pem.empty());
    // Said at the first failure and then once a minute (a worker pointed at a dead port
    // said nothing at all), with the TLS hint once.
    const double t = now_seconds();
    if (unreachable_since_ == 0) unreachable_since_ = t;
    if (unreachable_said_ == 0 || t - unreachable_said_ >= 60 || (!hint.empty() && !tls_hinted_)) {
      spdlog::warn("coordinator {} not reached for {:.0f} s: {}{}; retrying", options_.coordinator,
                   t - unreachable_since_, st.error_message(), tls_hinted_ ? "" : hint);
      unreachable_said_ = t;
      tls_hinted_ = tls_hinted_ || !hint.empty();
    } else {
      spdlog::debug("coordinator {}: {}; retrying", options_.coordinator, st.error_message());
    }
    backoff_.wait(&stop);
  }
  return false;
}

void Worker::fetch(const std::atomic<bool>& stop) {
  while (!stop) {
    if (options_.exit_when_idle_seconds > 0) {
      if (queue_->holds_tasks()) {
        last_work_ = now_seconds();
      } else if (now_seconds() - last_work_ > options_.exit_when_idle_seconds) {
        spdlog::info("no work for {:g} s (--exit-when-idle-seconds): leaving", options_.exit_when_idle_seconds);
        return;
      }
    }
    const Fetcher::Leased got = fetcher_->lease(stop);
    if (got.status.ok()) {
      last_contact_ = now_seconds();
      if (got.tasks > 0) last_work_ = now_seconds();
      rejoin_.reset();
      continue;
    }
    spdlog::debug("get task: {}", got.status.error_message());
    if (unreachable(got.status) && now_seconds() - last_contact_ < 0.5 * link_->lease_ms / 1000.0) {
      // A blip (a dropped connection, a stalled link): the coordinator holds this worker's
      // leases until they expire, and the lease keeper goes on renewing them, so keep the
      // work and ask again; only a longer silence (or "unknown worker") starts over.
      backoff_.wait(&stop);
      continue;
    }
    // Unknown worker (the coordinator restarted) or unreachable: its leases are gone.
    if (!unreachable(got.status))
      spdlog::warn("coordinator {} refused a request for work: {}; registering again", options_.coordinator,
                   got.status.error_message());
    queue_->drop_all();
    rejoin_.wait(&stop);
    if (!register_worker(stop)) return;  // stopped, or refused
  }
}

bool Worker::run(const std::atomic<bool>& stop) {
  last_work_ = now_seconds();
  if (!register_worker(stop)) return !refused_;
  {
    LeaseKeeper keeper(*link_, *queue_, stop);
    Sender sender(*link_, *queue_, {options_.threads, now_seconds(), options_.lie});
    RenderPool pool(*queue_, options_.threads);
    fetch(stop);
    queue_->stop();
  }  // joins the render threads, then the sender (finished results are sent first) and the keeper
  // What was not finished goes back, so another worker starts on it at once, and this
  // worker stops counting as one.
  const std::vector<uint64_t> unfinished = queue_->take_held();
  v1::UnregisterRequest bye;
  const Link::Identity me = link_->identity();
  bye.set_worker_id(me.id);
  bye.set_worker_secret(me.secret);
  v1::UnregisterResponse ok;
  if (!link_->stub->Unregister(link_->context(2).get(), bye, &ok).ok())
    for (uint64_t id : unfinished) link_->release(id);  // at least the leases, one by one
  return !refused_;
}

}  // namespace tessera
