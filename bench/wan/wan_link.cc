#include "bench/wan/wan_link.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <functional>
#include <stdexcept>
#include <vector>

namespace tessera::wan {

namespace {

using Clock = std::chrono::steady_clock;

int connect_to(const std::string& host, int port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res) != 0) return -1;
  int fd = -1;
  for (addrinfo* a = res; a && fd < 0; a = a->ai_next) {
    fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd >= 0 && connect(fd, a->ai_addr, a->ai_addrlen) != 0) {
      close(fd);
      fd = -1;
    }
  }
  freeaddrinfo(res);
  if (fd >= 0) {
    const int one = 1;
    setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  }
  return fd;
}

// One direction of a connection: a reader stamps each chunk with the time it reaches the
// far end (after the bottleneck and the delay), a writer delivers it then.
class Pipe {
 public:
  Pipe(int from, int to, LinkShape shape, std::atomic<uint64_t>& counter, std::function<void()> after_read)
      : from_(from), to_(to), shape_(shape), counter_(counter), after_read_(std::move(after_read)) {}
  ~Pipe() {
    if (reader_.joinable()) reader_.join();
    if (writer_.joinable()) writer_.join();
  }
  void start() {
    reader_ = std::thread([this] { read_loop(); });
    writer_ = std::thread([this] { write_loop(); });
  }
  void stop() {
    std::lock_guard<std::mutex> lock(mu_);
    stopped_ = true;
    cv_.notify_all();
  }

 private:
  struct Chunk {
    Clock::time_point at;
    std::string bytes;  // empty: end of stream
  };
  void read_loop() {
    std::vector<char> buf(16384);
    Clock::time_point free_at = Clock::now();  // when the bottleneck has sent all before
    while (true) {
      const ssize_t n = ::read(from_, buf.data(), buf.size());
      std::unique_lock<std::mutex> lock(mu_);
      if (n <= 0) {
        queue_.push_back(
            {Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(shape_.delay_s)),
             ""});
        cv_.notify_all();
        return;
      }
      const Clock::time_point now = Clock::now();
      Clock::time_point sent = now;
      if (shape_.rate_bytes_per_s > 0) {
        free_at = std::max(free_at, now) + std::chrono::duration_cast<Clock::duration>(
                                               std::chrono::duration<double>(double(n) / shape_.rate_bytes_per_s));
        sent = free_at;
      }
      queue_.push_back(
          {sent + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(shape_.delay_s)),
           std::string(buf.data(), size_t(n))});
      queued_ += size_t(n);
      cv_.notify_all();
      cv_.wait(lock, [&] { return stopped_ || queued_ < WanLink::queue_limit(shape_); });
      if (stopped_) return;
      lock.unlock();
      counter_ += uint64_t(n);
      if (after_read_) after_read_();  // (the counter includes these bytes)
    }
  }
  void write_loop() {
    while (true) {
      Chunk c;
      {
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return stopped_ || !queue_.empty(); });
        if (stopped_) return;
        const Clock::time_point at = queue_.front().at;
        if (cv_.wait_until(lock, at, [&] { return stopped_.load(); })) return;
        c = std::move(queue_.front());
        queue_.pop_front();
        queued_ -= c.bytes.size();
        cv_.notify_all();
      }
      if (c.bytes.empty()) {
        shutdown(to_, SHUT_WR);
        return;
      }
      for (size_t off = 0; off < c.bytes.size();) {
        const ssize_t w = ::send(to_, c.bytes.data() + off, c.bytes.size() - off, MSG_NOSIGNAL);
        if (w <= 0) {
          shutdown(from_, SHUT_RDWR);  // the other end is gone: so is this direction
          return;
        }
        off += size_t(w);
      }
    }
  }

  int from_, to_;
  LinkShape shape_;
  std::atomic<uint64_t>& counter_;
  std::function<void()> after_read_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Chunk> queue_;
  size_t queued_ = 0;
  std::atomic<bool> stopped_{false};
  std::thread reader_, writer_;
};

}  // namespace

size_t WanLink::queue_limit(const LinkShape& shape) {
  if (shape.rate_bytes_per_s <= 0) return kMaxQueuedBytes;
  return size_t(65536 + shape.rate_bytes_per_s * (shape.delay_s + std::max(0.1, 2 * shape.delay_s)));
}

struct WanLink::Conn {
  int client = -1, server = -1;
  std::unique_ptr<Pipe> up, down;
  std::atomic<bool> was_cut{false};
  // Whether this call cut it (false: it was cut before).
  bool cut() {
    if (was_cut.exchange(true)) return false;
    shutdown(client, SHUT_RDWR);
    shutdown(server, SHUT_RDWR);
    up->stop();
    down->stop();
    return true;
  }
  ~Conn() {
    up.reset();  // joins
    down.reset();
    close(client);
    close(server);
  }
};

WanLink::WanLink(const std::string& target_host, int target_port, LinkShape shape, int listen_port)
    : host_(target_host), target_port_(target_port), shape_(shape) {
  listen_fd_ = socket(AF_INET, SOCK_STREAM, 0);
  const int one = 1;
  setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(uint16_t(listen_port));
  if (listen_fd_ < 0 || bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
      listen(listen_fd_, 64) != 0) {
    const std::string why = std::strerror(errno);
    if (listen_fd_ >= 0) close(listen_fd_);
    throw std::runtime_error("wan link: cannot listen on 127.0.0.1:" + std::to_string(listen_port) + ": " + why);
  }
  socklen_t len = sizeof addr;
  getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = ntohs(addr.sin_port);
  acceptor_ = std::thread([this] { accept_loop(); });
}

WanLink::~WanLink() {
  stop_ = true;
  acceptor_.join();
  close(listen_fd_);
  std::list<std::shared_ptr<Conn>> conns;
  {
    std::lock_guard<std::mutex> lock(mu_);
    conns.swap(conns_);
  }
  for (auto& c : conns) c->cut();
  conns.clear();  // joins every pipe
}

void WanLink::accept_loop() {
  while (!stop_) {
    pollfd p{listen_fd_, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) continue;
    const int client = accept(listen_fd_, nullptr, nullptr);
    if (client < 0) continue;
    relay(client);
  }
}

void WanLink::relay(int client) {
  const int server = connect_to(host_, target_port_);
  if (server < 0) {
    close(client);
    return;
  }
  const int one = 1;
  setsockopt(client, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
  ++accepted_;
  auto c = std::make_shared<Conn>();
  c->client = client;
  c->server = server;
  Conn* raw = c.get();
  c->up = std::make_unique<Pipe>(client, server, shape_, up_, [this, raw] {
    int64_t at = cut_at_;
    if (at >= 0 && up_ >= uint64_t(at) && cut_at_.compare_exchange_strong(at, -1)) raw->cut();
  });
  c->down = std::make_unique<Pipe>(server, client, shape_, down_, nullptr);
  c->up->start();
  c->down->start();
  std::lock_guard<std::mutex> lock(mu_);
  conns_.push_back(std::move(c));
}

int WanLink::cut() {
  std::lock_guard<std::mutex> lock(mu_);
  int n = 0;
  for (auto& c : conns_) n += c->cut() ? 1 : 0;
  return n;
}

void WanLink::cut_after_upload(uint64_t bytes) { cut_at_ = int64_t(up_ + bytes); }

}  // namespace tessera::wan
