// The worker's line to the coordinator, shared by its parts: the stub (a real channel, or a
// fake coordinator in tests), the token sent with every call, and what registering gave:
// the worker's id and heartbeat interval, which change when it registers again.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>

#include "access.h"
#include "rpc.h"
#include "tessera.grpc.pb.h"

namespace tessera::worker {

struct Link {
  Link(std::shared_ptr<v1::TesseraWorker::StubInterface> s, Access a) : stub(std::move(s)), access(std::move(a)) {}
  std::shared_ptr<v1::TesseraWorker::StubInterface> stub;
  Access access;
  std::atomic<uint64_t> worker_id{0};
  std::atomic<uint32_t> heartbeat_ms{2000};

  std::unique_ptr<grpc::ClientContext> context(double seconds) const { return call_context(access, seconds); }
  // Gives a lease back early; `error` says why this worker could not render the task.
  // Best effort: an unanswered release expires like any lease.
  void release(uint64_t task_id, const std::string& error = "") const {
    v1::ReleaseRequest rel;
    rel.set_worker_id(worker_id);
    rel.set_task_id(task_id);
    rel.set_error(error);
    v1::ReleaseResponse rr;
    stub->ReleaseTask(context(2).get(), rel, &rr);
  }
};

}  // namespace tessera::worker
