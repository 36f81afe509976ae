// An httplib server serving on a thread of its own, and the probes every listener of the
// coordinator answers: what the status port (status_http) and the probes' own port
// (health_http) share.
#pragma once

#include <memory>
#include <string>
#include <thread>

#include "server/coordinator.h"

namespace httplib {
class Server;
}

namespace tessera {

class HttpListener {
 public:
  // `what` names the listener in errors ("http", "health"). A handler's unexpected
  // exception is logged (log_incident) and answered 500 with its incident number only.
  // Requests' bodies are held to kMaxBodyBytes (413 past it).
  HttpListener(std::unique_ptr<httplib::Server> server, std::string what);
  static constexpr size_t kMaxBodyBytes = 64 << 10;
  ~HttpListener();  // stops
  HttpListener(const HttpListener&) = delete;
  HttpListener& operator=(const HttpListener&) = delete;

  httplib::Server& server() { return *server_; }
  // Binds host:port (port 0 picks one) and returns the port; throws on failure.
  int bind(const std::string& host, int port);
  void start();  // serves on a thread until stop()
  void stop();

 private:
  std::unique_ptr<httplib::Server> server_;
  std::string what_;
  std::thread thread_;
};

// /healthz: 200 while the process serves HTTP. /readyz: 200 when the coordinator is ready,
// else 503 with its reason. Neither needs a token or says anything else.
void add_probes(httplib::Server& server, const Coordinator& coordinator);

}  // namespace tessera
