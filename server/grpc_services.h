// gRPC adapters over the Coordinator: translate messages and errors, nothing else.
#pragma once

#include <grpcpp/grpcpp.h>

#include "server/auth.h"
#include "server/coordinator.h"
#include "server/stream_slots.h"

namespace tessera {

// The coordinator's server settings, for the real server and the load benchmark alike:
// message limits, and enough gRPC threads kept alive between calls. (The sync server's
// default keeps 2 idle threads and ends the rest after each call, so a busy coordinator
// made and ended a thread for most calls, and its per-thread decoding scratch with it.)
// `max_message_bytes`: tests lower it (scenes of any size stream in pieces below it).
// Connections: one that has not finished its handshake (TCP to HTTP/2, TLS included)
// within `handshake_seconds` is closed, and one with no call for `idle_seconds` too (a
// client's channel reconnects by itself): idle sockets cannot pile up descriptors.
struct ConnectionLimits {
  double handshake_seconds = 10;
  double idle_seconds = 300;
};
void configure_server(grpc::ServerBuilder& builder, int max_message_bytes = kMaxMessageBytes,
                      ConnectionLimits limits = {});

// Refuses a call that carries no known token from its metadata alone, before its request is
// read (a handler checks the token only once the synchronous server has read the request
// whole, up to the message limit: a stranger's calls could make the coordinator hold that
// much each). The handler still checks the token's role. gRPC takes it on TLS server
// credentials only (ServerCredentials::SetAuthMetadataProcessor).
std::shared_ptr<grpc::AuthMetadataProcessor> token_gate(const Authenticator& auth);

// Without an Authenticator (or with an open one) every caller may do everything.
class ClientService final : public v1::Tessera::Service {
 public:
  explicit ClientService(Coordinator& c, const Authenticator* auth = nullptr)
      : c_(c),
        auth_(auth),
        streams_(c.options().max_streams_per_peer, "job watches, image downloads, scene uploads, submits") {}
  grpc::Status SubmitJob(grpc::ServerContext*, const v1::SubmitJobRequest* req, v1::JobId* out) override;
  grpc::Status GetJob(grpc::ServerContext*, const v1::JobId* req, v1::JobStatus* out) override;
  grpc::Status ListJobs(grpc::ServerContext*, const v1::ListJobsRequest*, v1::JobList* out) override;
  grpc::Status WatchJob(grpc::ServerContext* ctx, const v1::JobId* req, grpc::ServerWriter<v1::JobStatus>* w) override;
  grpc::Status CancelJob(grpc::ServerContext*, const v1::JobId* req, v1::JobStatus* out) override;
  grpc::Status RequeueJob(grpc::ServerContext*, const v1::JobId* req, v1::JobStatus* out) override;
  grpc::Status SetJobPriority(grpc::ServerContext*, const v1::SetPriorityRequest* req, v1::JobStatus* out) override;
  grpc::Status DeleteJob(grpc::ServerContext*, const v1::JobId* req, v1::DeleteJobResponse* out) override;
  grpc::Status ListEvents(grpc::ServerContext*, const v1::ListEventsRequest* req, v1::EventList* out) override;
  grpc::Status FetchImage(grpc::ServerContext*, const v1::FetchImageRequest* req, v1::Image* out) override;
  grpc::Status FetchImageChunks(grpc::ServerContext* ctx, const v1::FetchImageRequest* req,
                                grpc::ServerWriter<v1::ImageChunk>* w) override;
  grpc::Status UploadScene(grpc::ServerContext*, grpc::ServerReader<v1::SceneChunk>* reader,
                           v1::SceneUpload* out) override;

 private:
  Coordinator& c_;
  const Authenticator* auth_;
  // WatchJob, FetchImageChunks, UploadScene, and the unary calls that hold a thread long or
  // much memory (SubmitJob's scene check, FetchImage's whole image), per caller.
  StreamSlots streams_;
};

class WorkerService final : public v1::TesseraWorker::Service {
 public:
  explicit WorkerService(Coordinator& c, const Authenticator* auth = nullptr)
      : c_(c),
        auth_(auth),
        scene_streams_(c.options().max_streams_per_peer, "scene downloads"),
        polls_(c.options().max_streams_per_peer, "task requests"),
        peer_polls_(kPeerPollsPerStream * c.options().max_streams_per_peer, "task requests of all its workers",
                    std::to_string(kPeerPollsPerStream) + " x --max-streams-per-peer") {}
  grpc::Status Enrol(grpc::ServerContext*, const v1::EnrolRequest* req, v1::EnrolResponse* out) override;
  grpc::Status Register(grpc::ServerContext*, const v1::RegisterRequest* req, v1::RegisterResponse* out) override;
  grpc::Status GetTask(grpc::ServerContext*, const v1::GetTaskRequest* req, v1::GetTaskResponse* out) override;
  grpc::Status FetchSceneChunks(grpc::ServerContext* ctx, const v1::FetchSceneRequest* req,
                                grpc::ServerWriter<v1::SceneChunk>* w) override;
  grpc::Status Heartbeat(grpc::ServerContext*, const v1::HeartbeatRequest* req, v1::HeartbeatResponse* out) override;
  grpc::Status SubmitResults(grpc::ServerContext*, const v1::ResultBatch* req, v1::ResultAcks* out) override;
  grpc::Status ReleaseTask(grpc::ServerContext*, const v1::ReleaseRequest* req, v1::ReleaseResponse* out) override;
  grpc::Status Unregister(grpc::ServerContext*, const v1::UnregisterRequest* req, v1::UnregisterResponse*) override;

 private:
  Coordinator& c_;
  const Authenticator* auth_;
  StreamSlots scene_streams_;  // FetchSceneChunks, per worker (worker_stream_peer)
  StreamSlots polls_;          // GetTask's long polls (a second each), per registered worker
  // ... and per caller (worker_stream_peer: its address, or its token and address, or its own
  // credential): one caller registering 40 workers held 2,580 threads in polls.
  static constexpr size_t kPeerPollsPerStream = 4;
  StreamSlots peer_polls_;
};

}  // namespace tessera
