// The worker's line to the coordinator, shared by its parts: the stub (a real channel, or a
// fake coordinator in tests), the token sent with every call (an enrolled worker's own
// credential, which changes when it enrols again), and what registering gave: the worker's
// id and heartbeat interval, which change when it registers again.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "access.h"
#include "rpc.h"
#include "tessera.grpc.pb.h"

namespace tessera::worker {

struct Link {
  Link(std::shared_ptr<v1::TesseraWorker::StubInterface> s, Access a) : stub(std::move(s)), access_(std::move(a)) {}
  std::shared_ptr<v1::TesseraWorker::StubInterface> stub;
  std::atomic<uint32_t> heartbeat_ms{2000};
  std::atomic<uint32_t> lease_ms{10000};  // how long the coordinator keeps a silent worker's leases

  // Who this worker is since its last registration: the id and the secret that every
  // request carries with it (read together, so a request never mixes two registrations).
  struct Identity {
    uint64_t id = 0;
    std::string secret;
  };
  Identity identity() const {
    std::lock_guard<std::mutex> lock(mu_);
    return identity_;
  }
  void set_identity(Identity i) {
    std::lock_guard<std::mutex> lock(mu_);
    identity_ = std::move(i);
  }
  void set_token(std::string token) {  // the credential enrolling gave
    std::lock_guard<std::mutex> lock(mu_);
    access_.token = std::move(token);
  }

  std::unique_ptr<grpc::ClientContext> context(double seconds) const {
    std::lock_guard<std::mutex> lock(mu_);
    return call_context(access_, seconds);
  }
  // Gives a lease back early; `error` says why this worker could not render the task.
  // Best effort: an unanswered release expires like any lease.
  void release(uint64_t task_id, const std::string& error = "") const {
    v1::ReleaseRequest rel;
    const Identity me = identity();
    rel.set_worker_id(me.id);
    rel.set_worker_secret(me.secret);
    rel.set_task_id(task_id);
    rel.set_error(error);
    v1::ReleaseResponse rr;
    stub->ReleaseTask(context(2).get(), rel, &rr);
  }

 private:
  mutable std::mutex mu_;
  Access access_;
  Identity identity_;
};

}  // namespace tessera::worker
