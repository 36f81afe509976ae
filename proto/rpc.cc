#include "rpc.h"

#include <algorithm>
#include <chrono>
#include <thread>

#include "wire.h"

namespace tessera {

std::shared_ptr<grpc::Channel> coordinator_channel(const std::string& address, const Access& access,
                                                   int max_reconnect_backoff_ms) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  if (max_reconnect_backoff_ms > 0) args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, max_reconnect_backoff_ms);
  return grpc::CreateCustomChannel(address, channel_credentials(access), args);
}

std::unique_ptr<grpc::ClientContext> call_context(const Access& access, double seconds) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  authorize(*ctx, access);
  ctx->set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(int64_t(seconds * 1000)));
  return ctx;
}

bool unreachable(const grpc::Status& status) {
  return status.error_code() == grpc::StatusCode::UNAVAILABLE ||
         status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
}

std::string tls_hint(const grpc::Status& status, bool tls) {
  if (!unreachable(status)) return "";
  const std::string& m = status.error_message();
  if (!tls && (m.find("Socket closed") != std::string::npos || m.find("Connection reset") != std::string::npos))
    return " (a coordinator that serves TLS closes plaintext connections: give its certificate authority with "
           "--tls-ca FILE or $TESSERA_TLS_CA)";
  if (tls && (m.find("andshake") != std::string::npos || m.find("SSL") != std::string::npos ||
              m.find("ssl") != std::string::npos))
    return " (the TLS handshake failed: the coordinator may not serve TLS, or --tls-ca is not the authority that "
           "signed its certificate)";
  return "";
}

bool refused(const grpc::Status& status) {
  return status.error_code() == grpc::StatusCode::UNAUTHENTICATED ||
         status.error_code() == grpc::StatusCode::PERMISSION_DENIED ||
         status.error_code() == grpc::StatusCode::INVALID_ARGUMENT;
}

void Backoff::wait(const std::atomic<bool>* stop) {
  if (!stop) {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds_));
  } else {
    const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds_);
    while (!*stop && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  seconds_ = std::min(kMaxSeconds, seconds_ * 2);
}

}  // namespace tessera
