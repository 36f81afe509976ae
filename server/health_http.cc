#include "server/health_http.h"

#include <httplib.h>

#include <stdexcept>

namespace tessera {

HealthHttp::HealthHttp(const Coordinator& c) : server_(std::make_unique<httplib::Server>()) {
  // Probes answer at once or not at all: short timeouts, few threads, no keep-alive.
  server_->new_task_queue = [] { return new httplib::ThreadPool(4); };
  server_->set_read_timeout(2, 0);
  server_->set_write_timeout(2, 0);
  server_->set_keep_alive_max_count(1);
  server_->Get("/healthz",
               [](const httplib::Request&, httplib::Response& res) { res.set_content("ok\n", "text/plain"); });
  server_->Get("/readyz", [&c](const httplib::Request&, httplib::Response& res) {
    const std::string why = c.unready_reason();
    res.status = why.empty() ? 200 : 503;
    res.set_content(why.empty() ? "ready\n" : why + "\n", "text/plain");
  });
}

HealthHttp::~HealthHttp() { stop(); }

int HealthHttp::bind(const std::string& host, int port) {
  const int bound = port == 0 ? server_->bind_to_any_port(host) : (server_->bind_to_port(host, port) ? port : -1);
  if (bound <= 0) throw std::runtime_error("health: cannot bind " + host + ":" + std::to_string(port));
  return bound;
}

void HealthHttp::start() {
  thread_ = std::thread([this] { server_->listen_after_bind(); });
}

void HealthHttp::stop() {
  if (server_) server_->stop();
  if (thread_.joinable()) thread_.join();
}

}  // namespace tessera
