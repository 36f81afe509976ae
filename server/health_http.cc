#include "server/health_http.h"

#include <httplib.h>

namespace tessera {

std::unique_ptr<HttpListener> health_listener(const Coordinator& c) {
  auto server = std::make_unique<httplib::Server>();
  server->new_task_queue = [] { return new httplib::ThreadPool(4); };
  server->set_read_timeout(2, 0);
  server->set_write_timeout(2, 0);
  server->set_keep_alive_max_count(1);
  add_probes(*server, c);
  return std::make_unique<HttpListener>(std::move(server), "health");
}

}  // namespace tessera
