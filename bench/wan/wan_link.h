// A TCP relay that behaves like a long, narrow network link, for measuring and testing the
// farm across real distances on one machine (this kernel has no netem): every byte arrives
// `delay` after it was sent, and each direction carries at most `rate` bytes a second, sent
// one after another as through a bottleneck router. Each direction holds at most what is
// on the wire (rate x delay) plus a router's buffer of one round trip at the rate (the
// classic sizing; a few megabytes when the rate is unlimited); beyond that the relay stops
// reading, so the sender's TCP window closes as it would behind a real link, rather than
// seconds of results piling up in an endless buffer. A link can be cut, as a dropped
// connection is.
#pragma once

#include <atomic>
#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace tessera::wan {

struct LinkShape {
  double delay_s = 0;           // one way
  double rate_bytes_per_s = 0;  // each way; 0: unlimited
};

class WanLink {
 public:
  static constexpr size_t kMaxQueuedBytes = size_t(4) << 20;  // with no rate limit
  // What one direction holds at most (see above).
  static size_t queue_limit(const LinkShape& shape);

  // Listens on 127.0.0.1 (`listen_port` 0: any free port) and relays each connection to
  // target_host:target_port. Throws std::runtime_error if it cannot listen.
  WanLink(const std::string& target_host, int target_port, LinkShape shape, int listen_port = 0);
  ~WanLink();  // closes every connection
  WanLink(const WanLink&) = delete;
  WanLink& operator=(const WanLink&) = delete;

  int port() const { return port_; }
  // Cuts every open connection (both ends see it closed, mid-stream); later connections
  // are relayed as before. Returns how many were cut.
  int cut();
  // Cuts the connection that carries the client's `bytes`-th byte from now on (once).
  void cut_after_upload(uint64_t bytes);

  uint64_t bytes_up() const { return up_; }  // client to target, all connections
  uint64_t bytes_down() const { return down_; }
  int connections_accepted() const { return accepted_; }

 private:
  struct Conn;
  void accept_loop();
  void relay(int client);

  std::string host_;
  int target_port_;
  LinkShape shape_;
  int listen_fd_ = -1, port_ = 0;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> up_{0}, down_{0};
  std::atomic<int64_t> cut_at_{-1};  // in bytes_up(); -1: none armed
  std::atomic<int> accepted_{0};
  std::mutex mu_;  // guards conns_
  std::list<std::shared_ptr<Conn>> conns_;
  std::thread acceptor_;
};

}  // namespace tessera::wan
