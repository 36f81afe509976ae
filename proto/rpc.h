// How the client and the worker call the coordinator: one channel with the message limits,
// every call with the caller's token and a deadline, and what a failed call means (the
// coordinator out of reach: wait and try again; anything else is its answer).
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <memory>
#include <string>

#include "access.h"

namespace tessera {

// A channel to the coordinator at `address` (TLS when `access` has a CA) that carries
// messages up to kMaxMessageBytes. `max_reconnect_backoff_ms` > 0 caps gRPC's own wait
// between connection attempts (a worker wants the coordinator back quickly).
std::shared_ptr<grpc::Channel> coordinator_channel(const std::string& address, const Access& access,
                                                   int max_reconnect_backoff_ms = 0);

// A context for one call: the token (authorize) and a deadline `seconds` from now.
std::unique_ptr<grpc::ClientContext> call_context(const Access& access, double seconds);

// The coordinator could not be reached (down, restarting, a network blip): worth retrying.
bool unreachable(const grpc::Status& status);
// What an unreachable coordinator's error likely means where TLS is in question, as a
// sentence to append (empty where nothing points to it): a plaintext call that a TLS
// coordinator closed ("Socket closed"), or a TLS handshake that failed.
std::string tls_hint(const grpc::Status& status, bool tls);
// The coordinator will not take this caller (a bad or quarantined token, another protocol
// version): retrying cannot help.
bool refused(const grpc::Status& status);

// The wait before trying again a coordinator that went away: `first` seconds, doubling
// after each wait up to kMaxSeconds; reset() once a call gets through.
class Backoff {
 public:
  static constexpr double kClientFirstSeconds = 0.25;  // a person is waiting: say it, not often
  static constexpr double kWorkerFirstSeconds = 0.1;   // a worker idles while it waits
  static constexpr double kMaxSeconds = 5;

  explicit Backoff(double first_seconds) : first_(first_seconds), seconds_(first_seconds) {}
  double seconds() const { return seconds_; }  // the next wait
  // Sleeps the next wait, or until `stop` becomes true (looked at every 20 ms), then
  // doubles it.
  void wait(const std::atomic<bool>* stop = nullptr);
  void reset() { seconds_ = first_; }

 private:
  double first_;
  double seconds_;
};

}  // namespace tessera
