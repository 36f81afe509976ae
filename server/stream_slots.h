// Long-lived calls counted per caller. A stream (a client's WatchJob, FetchImageChunks or
// UploadScene; a worker's FetchSceneChunks) holds one of the gRPC server's threads while it
// lasts, so a caller opening a thousand of them made a thousand threads. Each caller (the
// services say who that is: grpc_services.cc) may hold `per_peer` at once; the next is
// refused with RESOURCE_EXHAUSTED naming what is counted and the flag.
#pragma once

#include <cstddef>
#include <map>
#include <mutex>
#include <string>

#include "server/request_error.h"

namespace tessera {

class StreamSlots {
 public:
  // `what`: the streams counted, for the error ("job watches, image downloads"); `flag`:
  // what sets per_peer, for the error too.
  StreamSlots(size_t per_peer, std::string what, std::string flag = "--max-streams-per-peer")
      : per_peer_(per_peer), what_(std::move(what)), flag_(std::move(flag)) {}

  // A stream's place, given back when it is destroyed.
  class Slot {
   public:
    Slot(StreamSlots* owner, std::string peer) : owner_(owner), peer_(std::move(peer)) {}
    Slot(const Slot&) = delete;
    Slot& operator=(const Slot&) = delete;
    ~Slot() { owner_->give_back(peer_); }

   private:
    StreamSlots* owner_;
    std::string peer_;
  };

  // Throws RequestError (kResourceExhausted) when `peer` holds per_peer streams already.
  [[nodiscard]] Slot take(const std::string& peer) {
    std::lock_guard<std::mutex> lock(mu_);
    size_t& n = held_[peer];
    if (n >= per_peer_)
      throw RequestError(RequestError::Code::kResourceExhausted, std::to_string(per_peer_) + " open streams (" + what_ +
                                                                     ") per caller at most (" + flag_ + ")");
    ++n;
    return Slot(this, peer);
  }

 private:
  void give_back(const std::string& peer) {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = held_.find(peer);
    if (it != held_.end() && --it->second == 0) held_.erase(it);
  }
  const size_t per_peer_;
  const std::string what_;
  const std::string flag_;
  std::mutex mu_;
  std::map<std::string, size_t> held_;
};

}  // namespace tessera
