// The probes' own listener (--health HOST:PORT): /healthz and /readyz, as on the status
// port, but on a socket and threads of their own, so that clients holding every thread of
// the status port (slow or idle connections) never make a liveness probe fail and the
// coordinator restart in a loop. Plain HTTP, no token: the answers say nothing, and the
// port is meant for the orchestrator (deploy/k8s probes it), not the public.
#pragma once

#include <memory>
#include <string>
#include <thread>

#include "server/coordinator.h"

namespace httplib {
class Server;
}

namespace tessera {

class HealthHttp {
 public:
  explicit HealthHttp(const Coordinator& coordinator);
  ~HealthHttp();
  // Binds host:port (port 0 picks one) and returns the port; throws on failure.
  int bind(const std::string& host, int port);
  void start();  // serves on a thread until stop()
  void stop();

 private:
  std::unique_ptr<httplib::Server> server_;
  std::thread thread_;
};

}  // namespace tessera
