// proto/rpc: the client's and the worker's back-off, and what a failed call means.
#include "rpc.h"

#include <gtest/gtest.h>

#include <chrono>

namespace tessera {
namespace {

TEST(Backoff, DoublesFromItsFirstWaitUpToFiveSecondsAndResets) {
  Backoff b(Backoff::kClientFirstSeconds);
  const std::atomic<bool> stopped{true};  // each wait returns at once, and still doubles
  for (double expected : {0.25, 0.5, 1.0, 2.0, 4.0, 5.0, 5.0}) {
    EXPECT_DOUBLE_EQ(b.seconds(), expected);
    b.wait(&stopped);
  }
  b.reset();
  EXPECT_DOUBLE_EQ(b.seconds(), 0.25);
  EXPECT_DOUBLE_EQ(Backoff(Backoff::kWorkerFirstSeconds).seconds(), 0.1);
}

TEST(Backoff, SleepsItsWaitUnlessStopped) {
  Backoff b(0.02);
  const auto t0 = std::chrono::steady_clock::now();
  b.wait();
  const std::atomic<bool> running{false};
  b.wait(&running);
  EXPECT_GE(std::chrono::steady_clock::now() - t0, std::chrono::milliseconds(60));  // 20 + 40 ms
  EXPECT_DOUBLE_EQ(b.seconds(), 0.08);
}

TEST(CallStatus, OnlyAnUnreachableCoordinatorIsWorthRetrying) {
  using C = grpc::StatusCode;
  EXPECT_TRUE(unreachable(grpc::Status(C::UNAVAILABLE, "connection refused")));
  EXPECT_TRUE(unreachable(grpc::Status(C::DEADLINE_EXCEEDED, "deadline")));
  for (C c : {C::OK, C::CANCELLED, C::NOT_FOUND, C::FAILED_PRECONDITION, C::INVALID_ARGUMENT, C::PERMISSION_DENIED,
              C::UNAUTHENTICATED, C::RESOURCE_EXHAUSTED, C::INTERNAL})
    EXPECT_FALSE(unreachable(grpc::Status(c, ""))) << int(c);
}

TEST(CallStatus, ABadTokenOrProtocolIsRefusedAndAForgottenWorkerIsNot) {
  using C = grpc::StatusCode;
  for (C c : {C::UNAUTHENTICATED, C::PERMISSION_DENIED, C::INVALID_ARGUMENT}) EXPECT_TRUE(refused(grpc::Status(c, "")));
  // "unknown worker; register again", a full farm, a coordinator away: worth another try.
  for (C c : {C::OK, C::FAILED_PRECONDITION, C::RESOURCE_EXHAUSTED, C::UNAVAILABLE, C::DEADLINE_EXCEEDED})
    EXPECT_FALSE(refused(grpc::Status(c, ""))) << int(c);
}

TEST(CallContext, HasADeadlineSecondsFromNow) {
  const auto before = std::chrono::system_clock::now();
  const auto ctx = call_context(Access{"secret", ""}, 30);
  EXPECT_GE(ctx->deadline(), before + std::chrono::seconds(30));
  EXPECT_LE(ctx->deadline(), std::chrono::system_clock::now() + std::chrono::seconds(30));
}

}  // namespace
}  // namespace tessera
