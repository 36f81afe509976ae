// The bounds on what one caller holds open at once, through the real binaries: a client's
// streams and long unary calls, a worker's scene downloads and long polls
// (--max-streams-per-peer).
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "core/io/files.h"
#include "tessera.grpc.pb.h"
#include "tests/integration/access_fixture.h"
#include "wire.h"

namespace tessera {
namespace {

// Issue 23: 1,000 WatchJob streams made 1,021 server threads. A caller holds at most
// --max-streams-per-peer streams at once; the next is refused naming the flag, and
// another caller's watch is not.
TEST_F(Access, StreamsAreBoundedPerCaller) {
  start_coordinator({"--max-streams-per-peer", "2"});
  const std::string id = submit(kAlice);  // no worker: it stays queued, so watches last
  auto stub = v1::Tessera::NewStub(grpc::CreateChannel(grpc_addr, grpc::InsecureChannelCredentials()));
  struct Watch {
    grpc::ClientContext ctx;
    std::unique_ptr<grpc::ClientReader<v1::JobStatus>> reader;
    v1::JobStatus first;
  };
  auto watch = [&](const char* token) {
    auto w = std::make_unique<Watch>();
    w->ctx.AddMetadata("authorization", std::string("Bearer ") + token);
    v1::JobId req;
    req.set_id(id);
    w->reader = stub->WatchJob(&w->ctx, req);
    return w;
  };
  std::vector<std::unique_ptr<Watch>> open;
  for (int i = 0; i < 2; ++i) {
    open.push_back(watch(kAlice));
    ASSERT_TRUE(open.back()->reader->Read(&open.back()->first));  // held open by the server
  }
  auto third = watch(kAlice);
  v1::JobStatus s;
  EXPECT_FALSE(third->reader->Read(&s));
  const grpc::Status refused = third->reader->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(refused.error_message().find("--max-streams-per-peer"), std::string::npos) << refused.error_message();
  {  // A scene upload is a stream too, held as long as its sender likes: the same slots.
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", std::string("Bearer ") + kAlice);
    v1::SceneUpload up;
    auto writer = stub->UploadScene(&ctx, &up);
    writer->WritesDone();
    const grpc::Status upload = writer->Finish();
    EXPECT_EQ(upload.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << upload.error_message();
    EXPECT_NE(upload.error_message().find("scene uploads"), std::string::npos) << upload.error_message();
  }
  {  // So are the unary calls that hold a thread long (a submit's scene check) or much memory
     // (a whole image), found by review uncounted.
    v1::JobId job;
    const grpc::Status submit = stub->SubmitJob(call(kAlice).get(), v1::SubmitJobRequest(), &job);
    EXPECT_EQ(submit.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << submit.error_message();
    EXPECT_NE(submit.error_message().find("submits) per caller"), std::string::npos) << submit.error_message();
    v1::FetchImageRequest fetch;
    fetch.set_id(id);
    v1::Image image;
    EXPECT_EQ(stub->FetchImage(call(kAlice).get(), fetch, &image).error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  }
  auto bobs = watch(kBob);
  EXPECT_TRUE(bobs->reader->Read(&s));
  for (auto& w : open) w->ctx.TryCancel();
  bobs->ctx.TryCancel();
  for (auto& w : open) w->reader->Finish();
  bobs->reader->Finish();
  // A stream closed gives its place back (once the server notices, within a second).
  bool watched = false;
  for (int i = 0; i < 30 && !watched; ++i) {
    auto again = watch(kAlice);
    watched = again->reader->Read(&s);
    again->ctx.TryCancel();
    again->reader->Finish();
    if (!watched) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(watched);
}

// A worker's scene download is a stream too: a reader that never reads holds a server
// thread. Counted per worker (its token and address here; its own credential where
// enrolled), apart from the clients' streams, so one worker cannot make a thread per call
// and a farm sharing a token is not counted as one caller.
TEST_F(Access, SceneDownloadsAreBoundedPerWorker) {
  start_coordinator({"--max-streams-per-peer", "2"});
  // 9 MB of triangles: more than the flow-control windows let through unread (the
  // channel's bandwidth probe is off, so they stay at their initial sizes).
  const int triangles = 1 << 18;
  std::string bin(size_t(triangles) * 36, '\0');
  for (int t = 0; t < triangles; ++t) {
    const float x = float(t % 512), y = float(t / 512);
    const float v[9] = {x, y, 0, x + 1, y, 0, x, y + 1, 0};
    std::memcpy(&bin[size_t(t) * 36], v, 36);
  }
  write_file_atomic((dir / "big.bin").string(), bin);
  const std::string scene = (dir / "big.gltf").string();
  write_file_atomic(scene, R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],)"
                           R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],)"
                           R"("accessors":[{"bufferView":0,"componentType":5126,"count":)" +
                               std::to_string(3 * triangles) +
                               R"(,"type":"VEC3","min":[0,0,0],"max":[512,512,0]}],)"
                               R"("bufferViews":[{"buffer":0,"byteLength":)" +
                               std::to_string(bin.size()) + R"(}],"buffers":[{"uri":"big.bin","byteLength":)" +
                               std::to_string(bin.size()) + "}]}");
  ASSERT_EQ(tessera("submit " + scene + " " + kFlags, kAlice).code, 0);
  grpc::ChannelArguments no_probe;
  no_probe.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  auto stub =
      v1::TesseraWorker::NewStub(grpc::CreateCustomChannel(grpc_addr, grpc::InsecureChannelCredentials(), no_probe));
  const v1::RegisterRequest reg = registration();
  v1::RegisterResponse me;
  ASSERT_TRUE(stub->Register(call(kWorker).get(), reg, &me).ok());
  v1::GetTaskRequest ask;
  ask.set_worker_id(me.worker_id());
  ask.set_worker_secret(me.worker_secret());
  v1::GetTaskResponse tasks;
  ASSERT_TRUE(stub->GetTask(call(kWorker).get(), ask, &tasks).ok());
  ASSERT_GT(tasks.tasks_size(), 0);
  struct Download {
    std::unique_ptr<grpc::ClientContext> ctx;
    std::unique_ptr<grpc::ClientReader<v1::SceneChunk>> reader;
  };
  v1::FetchSceneRequest req;
  req.set_scene_hash(tasks.tasks(0).scene_hash());
  auto download = [&](const char* token) {
    Download d{call(token), nullptr};
    d.reader = stub->FetchSceneChunks(d.ctx.get(), req);
    return d;
  };
  v1::SceneChunk chunk;
  auto close = [&](Download& d) {  // cancelled, read to its end
    d.ctx->TryCancel();
    while (d.reader->Read(&chunk)) {
    }
    d.reader->Finish();
  };
  std::vector<Download> open;
  for (int i = 0; i < 2; ++i) {
    open.push_back(download(kWorker));
    ASSERT_TRUE(open.back().reader->Read(&chunk));  // the manifest; the rest waits unread
  }
  Download third = download(kWorker);  // (read to its end uncancelled: the server's answer)
  while (third.reader->Read(&chunk)) {
  }
  const grpc::Status refused = third.reader->Finish();
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
  EXPECT_NE(refused.error_message().find("scene downloads"), std::string::npos) << refused.error_message();
  EXPECT_NE(refused.error_message().find("--max-streams-per-peer"), std::string::npos) << refused.error_message();
  // Another worker's are counted apart.
  Download other = download(kMallory);
  EXPECT_TRUE(other.reader->Read(&chunk));
  close(other);
  for (Download& d : open) close(d);
  // Closed streams give their places back (once the server notices): a whole download.
  bool whole = false;
  for (int i = 0; i < 30 && !whole; ++i) {
    Download again = download(kWorker);
    uint64_t bytes = 0;
    while (again.reader->Read(&chunk)) bytes += chunk.data().size();
    whole = again.reader->Finish().ok() && bytes >= bin.size();
    if (!whole) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(whole);
}

// `polls` sent at once under kWorker's token (no job: each waits its second): how many were
// answered and how many refused, each refusal RESOURCE_EXHAUSTED naming `refusal`. Sent
// again, up to five times, until `refusals` are, should the machine stall a poll past its
// second.
std::pair<int, int> polls_at_once(v1::TesseraWorker::Stub& workers, const std::vector<v1::GetTaskRequest>& polls,
                                  const std::string& refusal, int refusals) {
  int ok = 0, refused = 0;
  for (int attempt = 0; attempt < 5 && refused != refusals; ++attempt) {
    std::atomic<int> got_ok{0}, got_refused{0};
    std::vector<std::thread> polling;
    for (const v1::GetTaskRequest& poll : polls)
      polling.emplace_back([&] {
        v1::GetTaskResponse none;
        const grpc::Status st = workers.GetTask(call(kWorker).get(), poll, &none);
        if (st.ok()) {
          ++got_ok;
        } else {
          ++got_refused;
          EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
          EXPECT_NE(st.error_message().find(refusal), std::string::npos) << st.error_message();
        }
      });
    for (std::thread& t : polling) t.join();
    ok = got_ok, refused = got_refused;
  }
  return {ok, refused};
}

// Found by review: a worker's long polls (GetTask waits up to a second for work) were
// counted nowhere, so one worker could hold a server thread per call. At most
// --max-streams-per-peer at once per registered worker (its secret checked first); the next
// is refused naming what is counted. Three polls at once with room for two: one refused
// (tried again should the machine stall a poll past its second).
TEST_F(Access, AWorkersLongPollsAreBoundedPerWorker) {
  start_coordinator({"--max-streams-per-peer", "2"});  // no job: each poll waits its second
  auto workers = v1::TesseraWorker::NewStub(grpc::CreateChannel(grpc_addr, grpc::InsecureChannelCredentials()));
  v1::RegisterResponse w;
  ASSERT_TRUE(workers->Register(call(kWorker).get(), registration(), &w).ok());
  v1::GetTaskRequest poll;
  poll.set_worker_id(w.worker_id());
  poll.set_worker_secret(w.worker_secret());
  const auto [ok, refused] = polls_at_once(*workers, std::vector<v1::GetTaskRequest>(3, poll),
                                           "(task requests) per caller at most (--max-streams-per-peer)", 1);
  EXPECT_EQ(refused, 1);
  EXPECT_EQ(ok, 2);
  // Another worker has its own room.
  v1::RegisterResponse other;
  ASSERT_TRUE(workers->Register(call(kWorker).get(), registration(), &other).ok());
  poll.set_worker_id(other.worker_id());
  poll.set_worker_secret(other.worker_secret());
  v1::GetTaskResponse none;
  EXPECT_TRUE(workers->GetTask(call(kWorker).get(), poll, &none).ok());
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: the bound above is per registered worker, so one caller registering 40
// workers held 2,580 server threads in polls (registrations are cheap). The polls of all a
// caller's workers (its address, or its token and address) are bounded too: with
// --max-streams-per-peer 1, six workers' polls at once under one token, four answered.
TEST_F(Access, TheLongPollsOfACallersWorkersAreBoundedTogether) {
  start_coordinator({"--max-streams-per-peer", "1"});
  auto workers = v1::TesseraWorker::NewStub(grpc::CreateChannel(grpc_addr, grpc::InsecureChannelCredentials()));
  std::vector<v1::GetTaskRequest> polls(6);
  for (v1::GetTaskRequest& poll : polls) {
    v1::RegisterResponse w;
    ASSERT_TRUE(workers->Register(call(kWorker).get(), registration(), &w).ok());
    poll.set_worker_id(w.worker_id());
    poll.set_worker_secret(w.worker_secret());
  }
  const auto [ok, refused] = polls_at_once(
      *workers, polls, "(task requests of all its workers) per caller at most (4 x --max-streams-per-peer)", 2);
  EXPECT_EQ(refused, 2);
  EXPECT_EQ(ok, 4);
}

}  // namespace
}  // namespace tessera
