#include "server/http_listener.h"

#include <httplib.h>

#include <stdexcept>

namespace tessera {

HttpListener::HttpListener(std::unique_ptr<httplib::Server> server, std::string what)
    : server_(std::move(server)), what_(std::move(what)) {}

HttpListener::~HttpListener() { stop(); }

int HttpListener::bind(const std::string& host, int port) {
  const int bound = port == 0 ? server_->bind_to_any_port(host) : (server_->bind_to_port(host, port) ? port : -1);
  if (bound <= 0) throw std::runtime_error(what_ + ": cannot bind " + host + ":" + std::to_string(port));
  return bound;
}

void HttpListener::start() {
  thread_ = std::thread([this] { server_->listen_after_bind(); });
}

void HttpListener::stop() {
  server_->stop();
  if (thread_.joinable()) thread_.join();
}

void add_probes(httplib::Server& server, const Coordinator& c) {
  server.Get("/healthz",
             [](const httplib::Request&, httplib::Response& res) { res.set_content("ok\n", "text/plain"); });
  server.Get("/readyz", [&c](const httplib::Request&, httplib::Response& res) {
    const std::string why = c.unready_reason();
    res.status = why.empty() ? 200 : 503;
    res.set_content(why.empty() ? "ready\n" : why + "\n", "text/plain");
  });
}

}  // namespace tessera
