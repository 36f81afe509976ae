#include "server/http_listener.h"

#include <httplib.h>

#include <stdexcept>

#include "core/util/log.h"

namespace tessera {

HttpListener::HttpListener(std::unique_ptr<httplib::Server> server, std::string what)
    : server_(std::move(server)), what_(std::move(what)) {
  // A request's body is read whole before its handler runs (after the token check): with
  // cpp-httplib's default bound (none) one caller's POST could take all the memory. The
  // page's actions send a few bytes; a larger body is answered 413.
  server_->set_payload_max_length(kMaxBodyBytes);
  // A handler's unexpected exception: cpp-httplib's own answer put its text in an
  // EXCEPTION_WHAT header (a preview's named the image's path on the coordinator's disk);
  // the log has it, the caller a number, as on the gRPC side.
  server_->set_exception_handler(
      [w = what_](const httplib::Request& req, httplib::Response& res, std::exception_ptr ep) {
        std::string why = "unknown exception";
        try {
          std::rethrow_exception(ep);
        } catch (const std::exception& e) {
          why = e.what();
        } catch (...) {
        }
        res.status = 500;
        res.set_content(log_incident(w + " " + req.method + " " + req.path + ": " + why) + "\n", "text/plain");
      });
}

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
