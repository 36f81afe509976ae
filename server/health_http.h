// The probes' own listener (--health HOST:PORT): /healthz and /readyz, as on the status
// port, but on a socket and threads of their own, so that clients holding every thread of
// the status port (slow or idle connections) never make a liveness probe fail and the
// coordinator restart in a loop. Plain HTTP, no token: the answers say nothing, and the
// port is meant for the orchestrator (deploy/k8s probes it), not the public.
#pragma once

#include <memory>

#include "server/http_listener.h"

namespace tessera {

// Four threads, short timeouts, no keep-alive: probes answer at once or not at all.
std::unique_ptr<HttpListener> health_listener(const Coordinator& coordinator);

}  // namespace tessera
