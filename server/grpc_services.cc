#include "server/grpc_services.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

#include "core/util/cancel.h"
#include "core/util/invariant.h"
#include "core/util/log.h"
#include "server/histogram.h"

namespace tessera {
namespace {

// An unexpected failure: its details (which can name files on the coordinator's disk) go
// to the log only; the caller gets a number to find them by.
grpc::Status internal_error(const char* what) { return grpc::Status(grpc::StatusCode::INTERNAL, log_incident(what)); }

// The caller's address without its port ("ipv4:127.0.0.1:5000" -> "ipv4:127.0.0.1").
std::string peer_address(const std::string& peer) {
  const size_t colon = peer.rfind(':');
  return colon == std::string::npos || colon < 5 ? peer : peer.substr(0, colon);
}

// Whom a stream counts against: the token's name, or without tokens the caller's address.
std::string stream_peer(const Principal& who, const grpc::ServerContext& ctx) {
  return who.name.empty() ? peer_address(ctx.peer()) : "token " + who.name;
}
// A worker's: its own credential where enrolled; a worker token is often shared by a
// whole farm (a Slurm or Kubernetes deployment's), so there the token and the address.
std::string worker_stream_peer(const Principal& who, const grpc::ServerContext& ctx) {
  if (who.enrolled) return "worker " + who.name;
  return who.name.empty() ? peer_address(ctx.peer()) : "token " + who.name + " at " + peer_address(ctx.peer());
}

// Runs f, mapping the coordinator's errors to gRPC status codes.
template <typename F>
grpc::Status guarded(F&& f) {
  try {
    f();
    return grpc::Status::OK;
  } catch (const RequestError& e) {
    grpc::StatusCode code = grpc::StatusCode::INVALID_ARGUMENT;
    switch (e.code()) {
      case RequestError::Code::kInvalidArgument:
        break;
      case RequestError::Code::kNotFound:
        code = grpc::StatusCode::NOT_FOUND;
        break;
      case RequestError::Code::kFailedPrecondition:
        code = grpc::StatusCode::FAILED_PRECONDITION;
        break;
      case RequestError::Code::kResourceExhausted:
        code = grpc::StatusCode::RESOURCE_EXHAUSTED;
        break;
      case RequestError::Code::kPermissionDenied:
        code = grpc::StatusCode::PERMISSION_DENIED;
        break;
    }
    return grpc::Status(code, e.what());
  } catch (const Cancelled& e) {  // a scene check whose client went away, or a coordinator stopping
    return grpc::Status(grpc::StatusCode::CANCELLED, e.what());
  } catch (const InvariantError& e) {  // a bug, logged where it was found
    return internal_error(e.what());
  } catch (const std::exception& e) {
    return internal_error(e.what());
  }
}

// The caller, if its token allows `action`; otherwise the status to answer with.
grpc::Status caller(const Authenticator* auth, grpc::ServerContext* ctx, Action action, Principal* who) {
  if (!auth) {
    *who = Principal{"", Role::kAdmin};
    return grpc::Status::OK;
  }
  const auto& metadata = ctx->client_metadata();
  const auto it = metadata.find("authorization");
  const Authenticator::Check c = auth->check(
      it == metadata.end() ? std::string_view() : std::string_view(it->second.data(), it->second.size()), action);
  switch (c.outcome) {
    case Authenticator::Check::kAllowed:
      *who = c.who;
      return grpc::Status::OK;
    case Authenticator::Check::kUnauthenticated:
      return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, c.why + " (--token-file FILE or TESSERA_TOKEN)");
    case Authenticator::Check::kDenied:
      break;
  }
  return grpc::Status(grpc::StatusCode::PERMISSION_DENIED, c.why);
}

// Checks the caller, then runs f(principal) under guarded(); the time it takes goes to
// the method's tessera_rpc_seconds.
template <typename F>
grpc::Status as(const char* method, const Authenticator* auth, grpc::ServerContext* ctx, Action action, F&& f) {
  const auto since = std::chrono::steady_clock::now();
  Principal who;
  grpc::Status st = caller(auth, ctx, action, &who);
  if (st.ok()) st = guarded([&] { f(who); });
  RpcLatency::process().observe(method,
                                std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count());
  return st;
}

}  // namespace

namespace {

class TokenGate final : public grpc::AuthMetadataProcessor {
 public:
  explicit TokenGate(const Authenticator& auth) : auth_(auth) {}
  bool IsBlocking() const override { return false; }  // a lookup by digest: run it where the call is
  grpc::Status Process(const InputMetadata& metadata, grpc::AuthContext*, OutputMetadata*, OutputMetadata*) override {
    const auto it = metadata.find("authorization");
    const Authenticator::Check c =
        auth_.check(it == metadata.end() ? std::string_view() : std::string_view(it->second.data(), it->second.size()),
                    Action::kRead);  // (any known token passes here: the handler checks what it may do)
    if (c.outcome == Authenticator::Check::kUnauthenticated)
      return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, c.why + " (--token-file FILE or TESSERA_TOKEN)");
    return grpc::Status::OK;
  }

 private:
  const Authenticator& auth_;
};

}  // namespace

std::shared_ptr<grpc::AuthMetadataProcessor> token_gate(const Authenticator& auth) {
  return std::make_shared<TokenGate>(auth);
}

void configure_server(grpc::ServerBuilder& builder, int max_message_bytes, ConnectionLimits limits) {
  builder.AddChannelArgument(GRPC_ARG_SERVER_HANDSHAKE_TIMEOUT_MS, int(limits.handshake_seconds * 1000));
  builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_IDLE_MS, int(limits.idle_seconds * 1000));
  // A port another process listens on is refused, not shared (gRPC sets SO_REUSEPORT: a
  // second coordinator on the same address started silently and took half the calls).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.SetMaxReceiveMessageSize(max_message_bytes);
  builder.SetMaxSendMessageSize(max_message_bytes);
  const int cores = int(std::max(1u, std::thread::hardware_concurrency()));
  builder.SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::MAX_POLLERS, std::max(8, 2 * cores));
}

grpc::Status ClientService::SubmitJob(grpc::ServerContext* ctx, const v1::SubmitJobRequest* req, v1::JobId* out) {
  return as(__func__, auth_, ctx, Action::kSubmit, [&](const Principal& who) {
    const StreamSlots::Slot slot = streams_.take(stream_peer(who, *ctx));  // a scene check holds a thread
    // The scene check stops when the client goes away or the coordinator is told to stop.
    const CancelScope scope([ctx] { return ctx->IsCancelled(); });
    out->set_id(c_.submit(*req, who.name));
  });
}
grpc::Status ClientService::GetJob(grpc::ServerContext* ctx, const v1::JobId* req, v1::JobStatus* out) {
  return as(__func__, auth_, ctx, Action::kRead, [&](const Principal&) { *out = c_.status(req->id(), true); });
}
grpc::Status ClientService::ListJobs(grpc::ServerContext* ctx, const v1::ListJobsRequest* req, v1::JobList* out) {
  return as(__func__, auth_, ctx, Action::kRead,
            [&](const Principal&) { *out = c_.list(req->page_size(), req->page_token()); });
}
grpc::Status ClientService::WatchJob(grpc::ServerContext* ctx, const v1::JobId* req,
                                     grpc::ServerWriter<v1::JobStatus>* w) {
  // At most kUpdatesPerSecond updates (and always the last): a status with every tile on
  // every merge cost the render farm's cores more than the watcher gains.
  constexpr double kUpdatesPerSecond = 4;
  return as(__func__, auth_, ctx, Action::kRead, [&](const Principal& who) {
    const StreamSlots::Slot slot = streams_.take(stream_peer(who, *ctx));
    // Progress only: a watcher that wants every tile asks GetJob.
    v1::JobStatus s = c_.status(req->id(), false);
    const auto ended = [](const v1::JobStatus& st) { return !job_live(st.state()); };
    std::vector<std::string> sent;  // a sequence's frames as last sent: later messages carry what changed
    while (!ctx->IsCancelled()) {
      keep_changed_frames(s, sent);
      if (!w->Write(s) || ended(s)) return;
      const auto next = std::chrono::steady_clock::now() + std::chrono::duration<double>(1 / kUpdatesPerSecond);
      s = c_.wait_for_change(req->id(), s.samples_done(), 0.5);
      if (ended(s)) continue;
      // The end is never held back by the rate limit: the client is waiting for it.
      c_.wait_for_end(req->id(), std::chrono::duration<double>(next - std::chrono::steady_clock::now()).count());
      s = c_.status(req->id(), false);
    }
  });
}
grpc::Status ClientService::CancelJob(grpc::ServerContext* ctx, const v1::JobId* req, v1::JobStatus* out) {
  return as(__func__, auth_, ctx, Action::kCancel,
            [&](const Principal& who) { *out = c_.cancel(req->id(), who.name, who.role == Role::kAdmin); });
}
// Requeue, priority and delete: a client's own jobs, an admin's any (as CancelJob).
grpc::Status ClientService::RequeueJob(grpc::ServerContext* ctx, const v1::JobId* req, v1::JobStatus* out) {
  return as(__func__, auth_, ctx, Action::kCancel,
            [&](const Principal& who) { *out = c_.requeue(req->id(), who.name, who.role == Role::kAdmin); });
}
grpc::Status ClientService::SetJobPriority(grpc::ServerContext* ctx, const v1::SetPriorityRequest* req,
                                           v1::JobStatus* out) {
  return as(__func__, auth_, ctx, Action::kCancel, [&](const Principal& who) {
    *out = c_.set_priority(req->id(), req->priority(), who.name, who.role == Role::kAdmin);
  });
}
grpc::Status ClientService::DeleteJob(grpc::ServerContext* ctx, const v1::JobId* req, v1::DeleteJobResponse* out) {
  return as(__func__, auth_, ctx, Action::kCancel, [&](const Principal& who) {
    out->set_bytes_freed(c_.remove(req->id(), who.name, who.role == Role::kAdmin));
    out->set_id(req->id());
  });
}
grpc::Status ClientService::ListEvents(grpc::ServerContext* ctx, const v1::ListEventsRequest* req, v1::EventList* out) {
  return as(__func__, auth_, ctx, Action::kRead, [&](const Principal&) {
    *out = to_proto(c_.events(req->job_id(), req->after(), event_limit(req->limit()), !req->oldest()));
  });
}
grpc::Status ClientService::FetchImage(grpc::ServerContext* ctx, const v1::FetchImageRequest* req, v1::Image* out) {
  return as(__func__, auth_, ctx, Action::kRead, [&](const Principal& who) {
    const StreamSlots::Slot slot = streams_.take(stream_peer(who, *ctx));  // the whole image in memory
    const bool any = req->exr() || req->png();  // neither: both, as before the choice existed
    *out = c_.image(req->id(), req->exr() || !any, req->png() || !any,
                    req->has_frame() ? std::optional<int>(req->frame()) : std::nullopt);
  });
}

grpc::Status ClientService::UploadScene(grpc::ServerContext* ctx, grpc::ServerReader<v1::SceneChunk>* reader,
                                        v1::SceneUpload* out) {
  return as(__func__, auth_, ctx, Action::kSubmit, [&](const Principal& who) {
    const StreamSlots::Slot slot = streams_.take(stream_peer(who, *ctx));  // a slow upload holds a thread too
    *out = c_.upload_scene([&](v1::SceneChunk* chunk) { return reader->Read(chunk); }, who.name);
  });
}

grpc::Status ClientService::FetchImageChunks(grpc::ServerContext* ctx, const v1::FetchImageRequest* req,
                                             grpc::ServerWriter<v1::ImageChunk>* w) {
  return as(__func__, auth_, ctx, Action::kRead, [&](const Principal& who) {
    const StreamSlots::Slot slot = streams_.take(stream_peer(who, *ctx));
    c_.image_chunks(*req, [&](const v1::ImageChunk& c) { return !ctx->IsCancelled() && w->Write(c); });
  });
}

grpc::Status WorkerService::Enrol(grpc::ServerContext* ctx, const v1::EnrolRequest* req, v1::EnrolResponse* out) {
  return as(__func__, auth_, ctx, Action::kEnrol, [&](const Principal& who) {
    out->set_credential(c_.enrol(req->name(), who.name));  // (an event says so)
  });
}
grpc::Status WorkerService::Register(grpc::ServerContext* ctx, const v1::RegisterRequest* req,
                                     v1::RegisterResponse* out) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal& who) {
    if (!req->host().empty()) {
      *out = c_.register_worker(*req, who.name, who.enrolled);
      return;
    }
    v1::RegisterRequest named = *req;  // a worker from before hosts were sent: where it called from
    named.set_host(peer_address(ctx->peer()));
    *out = c_.register_worker(named, who.name, who.enrolled);
  });
}
grpc::Status WorkerService::GetTask(grpc::ServerContext* ctx, const v1::GetTaskRequest* req, v1::GetTaskResponse* out) {
  // Long poll: an idle worker waits here (up to a second) and gets a new job's first task
  // the moment it is submitted, instead of sleeping through a retry interval.
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal& who) {
    c_.check_worker(req->worker_id(), req->worker_secret());
    // Each poll holds a thread up to a second: counted per registered worker (its secret
    // checked), so one cannot hold a thread per call, and per caller, so registering more
    // workers does not give more (a worker polls once at a time: a host's many fit).
    const StreamSlots::Slot slot = polls_.take("worker " + std::to_string(req->worker_id()));
    const StreamSlots::Slot peer_slot = peer_polls_.take(worker_stream_peer(who, *ctx));
    const auto since = std::chrono::steady_clock::now(), until = since + std::chrono::seconds(1);
    while (true) {
      *out = c_.get_task(req->worker_id(), req->max_tasks(), req->max_samples(), req->max_passes());
      const auto now = std::chrono::steady_clock::now();
      if (out->tasks_size() > 0 || ctx->IsCancelled() || now >= until) {
        out->set_held_ms(uint32_t(std::chrono::duration_cast<std::chrono::milliseconds>(now - since).count()));
        return;
      }
      c_.wait_for_work(0.25);
    }
  });
}
grpc::Status WorkerService::FetchSceneChunks(grpc::ServerContext* ctx, const v1::FetchSceneRequest* req,
                                             grpc::ServerWriter<v1::SceneChunk>* w) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal& who) {
    const StreamSlots::Slot slot = scene_streams_.take(worker_stream_peer(who, *ctx));  // a slow reader holds a thread
    c_.scene_chunks(*req, [&](const v1::SceneChunk& chunk) { return !ctx->IsCancelled() && w->Write(chunk); });
  });
}
grpc::Status WorkerService::Heartbeat(grpc::ServerContext* ctx, const v1::HeartbeatRequest* req,
                                      v1::HeartbeatResponse* out) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal&) {
    c_.check_worker(req->worker_id(), req->worker_secret());
    for (uint64_t id :
         c_.heartbeat(req->worker_id(), {req->task_ids().begin(), req->task_ids().end()}, req->round_trip_us() / 1e6))
      out->add_refused(id);
  });
}
grpc::Status WorkerService::SubmitResults(grpc::ServerContext* ctx, const v1::ResultBatch* req, v1::ResultAcks* out) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal&) {
    const auto since = std::chrono::steady_clock::now();
    c_.check_worker(req->worker_id(), req->worker_secret());
    for (const v1::TaskResult& r : req->results())
      if (r.worker_id() != req->worker_id())
        throw RequestError(RequestError::Code::kPermissionDenied, "a result under worker " +
                                                                      std::to_string(r.worker_id()) + " in worker " +
                                                                      std::to_string(req->worker_id()) + "'s batch");
    const std::vector<const v1::TaskResult*> results(req->results().pointer_begin(), req->results().pointer_end());
    for (v1::ResultAck& ack : c_.submit_results(results)) *out->add_acks() = std::move(ack);
    out->set_held_ms(uint32_t(
        std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - since).count()));
  });
}
grpc::Status WorkerService::ReleaseTask(grpc::ServerContext* ctx, const v1::ReleaseRequest* req, v1::ReleaseResponse*) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal&) {
    c_.check_worker(req->worker_id(), req->worker_secret());
    c_.release(req->worker_id(), req->task_id(), req->error());
  });
}

grpc::Status WorkerService::Unregister(grpc::ServerContext* ctx, const v1::UnregisterRequest* req,
                                       v1::UnregisterResponse*) {
  return as(__func__, auth_, ctx, Action::kWork, [&](const Principal&) {
    c_.check_worker(req->worker_id(), req->worker_secret());
    c_.unregister(req->worker_id());
  });
}

}  // namespace tessera
