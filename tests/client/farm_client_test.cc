// The farm subcommands as functions, against a coordinator and a worker in this process:
// what `tessera submit/status/jobs/watch/fetch/cancel` print and write, without processes.
#include "client/farm_client.h"

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <thread>

#include "client/events_command.h"
#include "core/io/image_io.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "scene_bundle.h"
#include "server/grpc_services.h"
#include "tests/client/farm_client_fixture.h"
#include "tests/core/test_paths.h"
#include "worker/worker.h"

namespace tessera {
namespace {

// A stream of given pieces, as a coordinator would send them.
class CannedChunks : public grpc::ClientReaderInterface<v1::ImageChunk> {
 public:
  explicit CannedChunks(std::vector<v1::ImageChunk> chunks) : chunks_(std::move(chunks)) {}
  bool Read(v1::ImageChunk* out) override {
    if (next_ == chunks_.size()) return false;
    *out = chunks_[next_++];
    return true;
  }
  grpc::Status Finish() override { return grpc::Status::OK; }
  bool NextMessageSize(uint32_t* size) override {
    *size = 1 << 20;
    return next_ < chunks_.size();
  }
  void WaitForInitialMetadata() override {}

 private:
  std::vector<v1::ImageChunk> chunks_;
  size_t next_ = 0;
};

// The real coordinator's stub, but the first fetch of each image is answered as a
// coordinator killed just after saying the job ended would answer it once restarted: it
// took the job up again from an earlier checkpoint and serves its progressive image, not
// final (here: bytes that are no EXR at all, so writing them could not pass unnoticed).
class RestartedOnceStub : public v1::Tessera::StubInterface {
 public:
  explicit RestartedOnceStub(v1::Tessera::StubInterface& real) : real_(real) {}
  grpc::Status SubmitJob(grpc::ClientContext* c, const v1::SubmitJobRequest& r, v1::JobId* o) override {
    return real_.SubmitJob(c, r, o);
  }
  grpc::Status GetJob(grpc::ClientContext* c, const v1::JobId& r, v1::JobStatus* o) override {
    return real_.GetJob(c, r, o);
  }
  grpc::Status ListJobs(grpc::ClientContext* c, const v1::ListJobsRequest& r, v1::JobList* o) override {
    return real_.ListJobs(c, r, o);
  }
  grpc::Status CancelJob(grpc::ClientContext* c, const v1::JobId& r, v1::JobStatus* o) override {
    return real_.CancelJob(c, r, o);
  }
  grpc::Status RequeueJob(grpc::ClientContext* c, const v1::JobId& r, v1::JobStatus* o) override {
    return real_.RequeueJob(c, r, o);
  }
  grpc::Status SetJobPriority(grpc::ClientContext* c, const v1::SetPriorityRequest& r, v1::JobStatus* o) override {
    return real_.SetJobPriority(c, r, o);
  }
  grpc::Status DeleteJob(grpc::ClientContext* c, const v1::JobId& r, v1::DeleteJobResponse* o) override {
    return real_.DeleteJob(c, r, o);
  }
  grpc::Status ListEvents(grpc::ClientContext* c, const v1::ListEventsRequest& r, v1::EventList* o) override {
    return real_.ListEvents(c, r, o);
  }
  grpc::ClientWriterInterface<v1::SceneChunk>* UploadSceneRaw(grpc::ClientContext* c, v1::SceneUpload* o) override {
    return real_.UploadScene(c, o).release();
  }
  grpc::Status FetchImage(grpc::ClientContext* c, const v1::FetchImageRequest& r, v1::Image* o) override {
    return real_.FetchImage(c, r, o);
  }
  int not_final = 0;

 private:
  grpc::ClientReaderInterface<v1::JobStatus>* WatchJobRaw(grpc::ClientContext* c, const v1::JobId& r) override {
    return real_.WatchJob(c, r).release();
  }
  grpc::ClientReaderInterface<v1::ImageChunk>* FetchImageChunksRaw(grpc::ClientContext* c,
                                                                   const v1::FetchImageRequest& r) override {
    if (!served_.insert(r.id() + "#" + std::to_string(r.frame())).second) return real_.FetchImageChunks(c, r).release();
    ++not_final;
    v1::ImageChunk chunk;
    chunk.set_data("a progressive image");
    chunk.set_size(chunk.data().size());
    chunk.set_version("v1");
    chunk.set_final(false);
    chunk.set_last(true);
    return new CannedChunks({chunk});
  }
  grpc::ClientAsyncReaderInterface<v1::ImageChunk>* AsyncFetchImageChunksRaw(grpc::ClientContext*,
                                                                             const v1::FetchImageRequest&,
                                                                             grpc::CompletionQueue*, void*) override {
    return nullptr;
  }
  grpc::ClientAsyncReaderInterface<v1::ImageChunk>* PrepareAsyncFetchImageChunksRaw(grpc::ClientContext*,
                                                                                    const v1::FetchImageRequest&,
                                                                                    grpc::CompletionQueue*) override {
    return nullptr;
  }
#define TESSERA_NO_ASYNC(Rpc, Request, Response)                                                                   \
  grpc::ClientAsyncResponseReaderInterface<Response>* Async##Rpc##Raw(grpc::ClientContext*, const Request&,        \
                                                                      grpc::CompletionQueue*) override {           \
    return nullptr;                                                                                                \
  }                                                                                                                \
  grpc::ClientAsyncResponseReaderInterface<Response>* PrepareAsync##Rpc##Raw(grpc::ClientContext*, const Request&, \
                                                                             grpc::CompletionQueue*) override {    \
    return nullptr;                                                                                                \
  }
  TESSERA_NO_ASYNC(SubmitJob, v1::SubmitJobRequest, v1::JobId)
  TESSERA_NO_ASYNC(GetJob, v1::JobId, v1::JobStatus)
  TESSERA_NO_ASYNC(ListJobs, v1::ListJobsRequest, v1::JobList)
  TESSERA_NO_ASYNC(CancelJob, v1::JobId, v1::JobStatus)
  TESSERA_NO_ASYNC(RequeueJob, v1::JobId, v1::JobStatus)
  TESSERA_NO_ASYNC(SetJobPriority, v1::SetPriorityRequest, v1::JobStatus)
  TESSERA_NO_ASYNC(DeleteJob, v1::JobId, v1::DeleteJobResponse)
  TESSERA_NO_ASYNC(FetchImage, v1::FetchImageRequest, v1::Image)
  TESSERA_NO_ASYNC(ListEvents, v1::ListEventsRequest, v1::EventList)
#undef TESSERA_NO_ASYNC
  grpc::ClientAsyncWriterInterface<v1::SceneChunk>* AsyncUploadSceneRaw(grpc::ClientContext*, v1::SceneUpload*,
                                                                        grpc::CompletionQueue*, void*) override {
    return nullptr;
  }
  grpc::ClientAsyncWriterInterface<v1::SceneChunk>* PrepareAsyncUploadSceneRaw(grpc::ClientContext*, v1::SceneUpload*,
                                                                               grpc::CompletionQueue*) override {
    return nullptr;
  }
  grpc::ClientAsyncReaderInterface<v1::JobStatus>* AsyncWatchJobRaw(grpc::ClientContext*, const v1::JobId&,
                                                                    grpc::CompletionQueue*, void*) override {
    return nullptr;
  }
  grpc::ClientAsyncReaderInterface<v1::JobStatus>* PrepareAsyncWatchJobRaw(grpc::ClientContext*, const v1::JobId&,
                                                                           grpc::CompletionQueue*) override {
    return nullptr;
  }
  v1::Tessera::StubInterface& real_;
  std::set<std::string> served_;
};

// submit --wait writes only final images: one that is not (the coordinator restarted after
// saying the job ended and renders it again) is fetched again once the job has ended
// again, and the file is the whole image. (Found as a flaky kill test: a frame written with
// 7 of its 8 passes.)
TEST_F(FarmClient, SubmitWaitWritesNoImageThatIsNotFinal) {
  start_worker();
  RestartedOnceStub restarted(*stub);
  const std::string exr = (dir / "farm.exr").string();
  SubmitRequest r = request({exr});
  r.wait = true;
  ASSERT_EQ(submit_job(restarted, r, ctx), 0) << err.text();
  EXPECT_EQ(restarted.not_final, 1);
  const Film local = render_image(TileRenderer(load_scene(r.flags.scene), to_settings(r.flags)), 2).film;
  const ExrImage img = read_exr(exr);  // an EXR: not the bytes of the progressive answer
  for (size_t i = 0; i < local.pixels().size(); ++i) ASSERT_EQ(img.channels.at("spp")[i], float(local.pixels()[i].n));
}

TEST_F(FarmClient, SubmitWaitWritesNoFrameThatIsNotFinal) {
  start_worker();
  RestartedOnceStub restarted(*stub);
  const std::string pattern = (dir / "f.####.exr").string();
  SubmitRequest r = request({pattern});
  r.flags.frames = "1-2";
  r.wait = true;
  ASSERT_EQ(submit_job(restarted, r, ctx), 0) << err.text();
  EXPECT_EQ(restarted.not_final, 2);
  for (int f : {1, 2}) {
    RenderFlags flags = r.flags;
    flags.frames.clear();
    flags.settings.frame = f;
    const Film local = render_image(TileRenderer(load_scene(r.flags.scene), to_settings(flags)), 2).film;
    const ExrImage img = read_exr((dir / ("f.000" + std::to_string(f) + ".exr")).string());
    for (size_t i = 0; i < local.pixels().size(); ++i)
      ASSERT_EQ(img.channels.at("spp")[i], float(local.pixels()[i].n)) << "frame " << f;
  }
}

TEST(WatchUpdates, AChangedOnlyMessageReplacesItsFramesByNumberAndKeepsTheOthers) {
  v1::JobStatus held, whole;
  for (int f : {5, 6, 7}) whole.add_frames()->set_frame(f);
  whole.set_frames_done(0);
  apply_watch_update(held, whole);
  EXPECT_EQ(held.frames_size(), 3);
  v1::JobStatus update;
  update.set_frames_changed_only(true);
  update.set_frames_done(1);
  v1::FrameStatus* six = update.add_frames();
  six->set_frame(6);
  six->set_state(v1::JobStatus::DONE);
  apply_watch_update(held, update);
  ASSERT_EQ(held.frames_size(), 3);
  EXPECT_FALSE(held.frames_changed_only());
  EXPECT_EQ(held.frames_done(), 1u);  // the rest of the message is the new status
  EXPECT_EQ(held.frames(0).frame(), 5);
  EXPECT_EQ(held.frames(1).state(), v1::JobStatus::DONE);
  EXPECT_EQ(held.frames(2).frame(), 7);
  apply_watch_update(held, whole);  // a whole message (a new stream's first): replaces all
  EXPECT_EQ(held.frames(1).state(), v1::JobStatus::QUEUED);
}

TEST_F(FarmClient, AWatchedSequenceSendsEveryFrameOnceThenOnlyFramesThatChanged) {
  SubmitRequest r = request({});
  r.flags.resolution = {16, 16};
  v1::SubmitJobRequest req;
  req.set_version(kProtocolVersion);
  std::string main;
  pack_scene(r.flags.scene, &main, req.mutable_files());
  req.set_main_file(main);
  *req.mutable_settings() = to_proto(to_settings(r.flags));
  for (int f = 1; f <= 6; ++f) req.add_frames(f);
  grpc::ClientContext submit_ctx;
  v1::JobId id;
  ASSERT_TRUE(stub->SubmitJob(&submit_ctx, req, &id).ok());
  grpc::ClientContext watch_ctx;
  auto reader = stub->WatchJob(&watch_ctx, id);
  v1::JobStatus got, held;
  ASSERT_TRUE(reader->Read(&got));
  EXPECT_FALSE(got.frames_changed_only()) << "a stream's first message holds every frame";
  EXPECT_EQ(got.frames_size(), 6);
  apply_watch_update(held, got);
  // No worker yet: nothing moves, and the next update (after the watch's wait) says so
  // without a frame.
  ASSERT_TRUE(reader->Read(&got));
  EXPECT_TRUE(got.frames_changed_only());
  EXPECT_EQ(got.frames_size(), 0);
  apply_watch_update(held, got);
  start_worker();
  while (reader->Read(&got)) {
    EXPECT_TRUE(got.frames_changed_only());
    apply_watch_update(held, got);
  }
  EXPECT_TRUE(reader->Finish().ok());
  EXPECT_EQ(held.state(), v1::JobStatus::DONE);
  ASSERT_EQ(held.frames_size(), 6);
  for (const v1::FrameStatus& f : held.frames()) EXPECT_EQ(f.state(), v1::JobStatus::DONE) << f.frame();
}

TEST_F(FarmClient, SubmitWaitsAndWritesTheLocalImageThenListsStatusAndFetch) {
  start_worker();
  const std::string exr = (dir / "farm.exr").string(), png = (dir / "farm.png").string();
  SubmitRequest r = request({exr, png});
  r.wait = true;
  r.name = "cornell";
  ctx.json = true;
  ASSERT_EQ(submit_job(*stub, r, ctx), 0) << err.text();
  const nlohmann::json final = nlohmann::json::parse(out.text());
  EXPECT_EQ(final["state"], "DONE");
  EXPECT_EQ(final["name"], "cornell");
  // 64-bit counts are JSON numbers (protobuf's own JSON writes them as strings).
  EXPECT_TRUE(final["samples_done"].is_number_unsigned()) << final["samples_done"];
  EXPECT_EQ(final["samples_done"], final["samples_total"]);
  const std::string id = final["id"];
  // The image is `tessera render`'s, in every channel.
  const Scene scene = load_scene(r.flags.scene);
  const Film local = render_image(TileRenderer(scene, to_settings(r.flags)), 2).film;
  const ExrImage img = read_exr(exr);
  ASSERT_EQ(img.width, 40);
  for (size_t i = 0; i < local.pixels().size(); ++i) {
    const Rgb m = local.pixels()[i].mean();
    ASSERT_EQ(std::memcmp(&m.r, &img.channels.at("R")[i], 4), 0) << i;
    ASSERT_EQ(img.channels.at("spp")[i], float(local.pixels()[i].n)) << i;
  }
  EXPECT_TRUE(fs::file_size(png) > 8);

  ctx.json = false;
  Output listing;
  ctx.out = listing.file();
  EXPECT_EQ(list_jobs(*stub, ctx), 0);
  EXPECT_NE(listing.text().find(id + "  DONE"), std::string::npos) << listing.text();
  EXPECT_NE(listing.text().find("  SUBMITTED  "), std::string::npos) << listing.text();
  // Issue 24: when it was submitted, started and ended, in --json as RFC 3339 times.
  ctx.json = true;
  Output as_json;
  ctx.out = as_json.file();
  EXPECT_EQ(show_status(*stub, id, ctx), 0);
  const nlohmann::json j = nlohmann::json::parse(as_json.text());
  const std::regex rfc3339(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?Z)");
  for (const char* t : {"submitted_at", "started_at", "ended_at"}) {
    ASSERT_TRUE(j.contains(t)) << as_json.text();
    EXPECT_TRUE(std::regex_match(j[t].get<std::string>(), rfc3339)) << j[t];
  }
  EXPECT_LE(j["submitted_at"].get<std::string>(), j["started_at"].get<std::string>());
  EXPECT_LE(j["started_at"].get<std::string>(), j["ended_at"].get<std::string>());
  ctx.json = false;
  Output one;
  ctx.out = one.file();
  EXPECT_EQ(show_status(*stub, id, ctx), 0);
  EXPECT_NE(one.text().find("elapsed"), std::string::npos) << one.text();
  EXPECT_EQ(watch_job(*stub, id, ctx), 0);  // an ended job: at once, DONE
  const std::string again = (dir / "again.exr").string();
  EXPECT_EQ(fetch_image(*stub, id, {again}, ctx), 0);
  EXPECT_EQ(read_exr(again).channels.at("R"), img.channels.at("R"));

  // `tessera events JOB`: its life under a header; --json with numbers and RFC 3339 times.
  Output events;
  ctx.out = events.file();
  EXPECT_EQ(list_events(*stub, {id}, ctx), 0);
  EXPECT_EQ(events.text().rfind(kEventsHeader, 0), 0u) << events.text();
  for (const char* kind : {"job.submitted", "job.started", "job.done"})
    EXPECT_NE(events.text().find(kind), std::string::npos) << events.text();
  ctx.json = true;
  Output events_json;
  ctx.out = events_json.file();
  EXPECT_EQ(list_events(*stub, {id}, ctx), 0);
  const nlohmann::json ev = nlohmann::json::parse(events_json.text())["events"];
  ASSERT_EQ(ev.size(), 3u) << events_json.text();
  EXPECT_TRUE(ev[0]["id"].is_number_unsigned()) << ev[0];
  EXPECT_TRUE(std::regex_match(ev[0]["time"].get<std::string>(), rfc3339)) << ev[0];
  EXPECT_EQ(ev[0]["kind"], "job.submitted");
  EXPECT_EQ(ev[0]["job_id"], id);
}

// Issue 22: a scene larger than any one message the coordinator takes or sends (here 64
// KiB each way: a glTF of 454 KB and an environment map of 131 KB) streams in pieces, up
// to the coordinator's disk and down to the worker's, and the image is tessera render's.
// The same scene in one message is refused by gRPC itself.
TEST_F(FarmClient, ASceneLargerThanAnyMessageStreamsThroughAndRendersAsLocally) {
  server->Shutdown();
  max_message_bytes = 64 << 10;
  address = "127.0.0.1:" + std::to_string(serve(0));
  stub = connect_coordinator(address);
  ctx.coordinator = address;
  ctx.scene_chunk_bytes = 24 << 10;
  start_worker();
  const std::string exr = (dir / "farm.exr").string();
  SubmitRequest r = request({exr});
  r.flags.scene = testing::source_path("scenes/cornell-spheres.gltf");
  r.flags.settings.environment_map = testing::source_path("scenes/sky.hdr");
  r.wait = true;
  ASSERT_GT(fs::file_size(r.flags.scene), size_t(max_message_bytes));
  ASSERT_EQ(submit_job(*stub, r, ctx), 0) << err.text();
  const Film local = render_image(TileRenderer(load_scene(r.flags.scene), to_settings(r.flags)), 2).film;
  const ExrImage img = read_exr(exr);
  for (size_t i = 0; i < local.pixels().size(); ++i) {
    const Rgb m = local.pixels()[i].mean();
    ASSERT_EQ(std::memcmp(&m.r, &img.channels.at("R")[i], 4), 0) << i;
    ASSERT_EQ(std::memcmp(&m.g, &img.channels.at("G")[i], 4), 0) << i;
    ASSERT_EQ(std::memcmp(&m.b, &img.channels.at("B")[i], 4), 0) << i;
    ASSERT_EQ(img.channels.at("spp")[i], float(local.pixels()[i].n)) << i;
  }
  v1::SubmitJobRequest whole;  // the old way: every byte in one message
  whole.set_version(kProtocolVersion);
  std::string main;
  pack_scene(r.flags.scene, &main, whole.mutable_files());
  whole.set_main_file(main);
  *whole.mutable_settings() = to_proto(to_settings(r.flags));
  v1::JobId id;
  grpc::ClientContext call;
  EXPECT_EQ(stub->SubmitJob(&call, whole, &id).error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
}

TEST_F(FarmClient, ErrorsNameTheProblem) {
  try {
    show_status(*stub, "no-such-job", ctx);
    ADD_FAILURE();
  } catch (const FarmError& e) {
    EXPECT_NE(std::string(e.what()).find("no job 'no-such-job'"), std::string::npos) << e.what();
  }
  // An unknown output format is a usage error (exit 2), found before any download.
  EXPECT_THROW(fetch_image(*stub, "x", {(dir / "out.tiff").string()}, ctx), CLI::ValidationError);
  SubmitRequest bad = request({});
  bad.flags.settings.spp = 0;
  EXPECT_THROW(submit_job(*stub, bad, ctx), CLI::ValidationError);
  auto gone = connect_coordinator("127.0.0.1:1");
  FarmContext c = ctx;
  c.coordinator = "127.0.0.1:1";
  try {
    list_jobs(*gone, c);
    ADD_FAILURE();
  } catch (const FarmError& e) {
    EXPECT_NE(std::string(e.what()).find("coordinator 127.0.0.1:1 unreachable"), std::string::npos) << e.what();
  }
}

TEST_F(FarmClient, CancelKeepsTheJobAndSaysCancelled) {
  SubmitRequest r = request({});
  r.flags.settings.spp = 1 << 20;  // no worker: it stays queued
  ASSERT_EQ(submit_job(*stub, r, ctx), 0);
  std::string id = out.text();
  id.erase(id.find_last_not_of("\n") + 1);
  Output c;
  ctx.out = c.file();
  EXPECT_EQ(cancel_job(*stub, id, ctx), 0);
  EXPECT_NE(c.text().find("CANCELLED"), std::string::npos) << c.text();
  EXPECT_EQ(watch_job(*stub, id, ctx), 1);  // ended, but not DONE
}

// The coordinator goes away while a client watches (here its server stops and comes back
// on the same port): the watch reconnects with back-off and sees the job end.
TEST_F(FarmClient, WatchReconnectsWhenTheCoordinatorComesBack) {
  SubmitRequest r = request({(dir / "x.exr").string()});
  ASSERT_EQ(submit_job(*stub, r, ctx), 0) << err.text();
  std::string id = out.text();
  id.erase(id.find_last_not_of('\n') + 1);
  const int port = std::stoi(address.substr(address.rfind(':') + 1));
  std::atomic<int> code{-1};
  FarmContext quiet = ctx;
  Output watched;
  quiet.out = watched.file();
  std::thread watcher([&] { code = watch_job(*stub, id, quiet); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  server->Shutdown(std::chrono::system_clock::now());  // the watch loses its stream
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  ASSERT_EQ(serve(port), port);
  start_worker();  // the job can only end after the coordinator is back
  watcher.join();
  EXPECT_EQ(code, 0) << err.text();
  EXPECT_NE(watched.text().find("DONE"), std::string::npos) << watched.text();
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Issue 24: job ids may be given by a prefix only one job's id has (as git and docker take
// them); one several jobs share is refused naming them, one no job has too; a whole id, a
// frame's id, or something that is not hex goes to the coordinator as it is.
TEST_F(FarmClient, AJobIdPrefixNamesTheOneJobWithIt) {
  v1::SubmitJobRequest req;
  req.set_version(kProtocolVersion);
  std::string main;
  SubmitRequest r = request({});
  pack_scene(r.flags.scene, &main, req.mutable_files());
  req.set_main_file(main);
  r.flags.resolution = {8, 8};
  *req.mutable_settings() = to_proto(to_settings(r.flags));
  std::vector<std::string> ids;
  for (int i = 0; i < 17; ++i) {  // 17 ids: two share a first hex digit
    grpc::ClientContext call;
    v1::JobId id;
    ASSERT_TRUE(stub->SubmitJob(&call, req, &id).ok());
    ids.push_back(id.id());
  }
  for (const std::string& id : ids) EXPECT_EQ(resolve_job_id(*stub, id.substr(0, 12), ctx), id);
  std::string shared;
  for (size_t a = 0; a < ids.size() && shared.empty(); ++a)
    for (size_t b = a + 1; b < ids.size() && shared.empty(); ++b)
      if (ids[a][0] == ids[b][0]) shared = ids[a].substr(0, 1);
  ASSERT_FALSE(shared.empty());
  try {
    resolve_job_id(*stub, shared, ctx);
    ADD_FAILURE() << "an ambiguous prefix was taken";
  } catch (const FarmError& e) {
    EXPECT_NE(std::string(e.what()).find("job id prefix '" + shared + "' is ambiguous"), std::string::npos) << e.what();
  }
  EXPECT_EQ(resolve_job_id(*stub, ids[0], ctx), ids[0]);
  EXPECT_EQ(resolve_job_id(*stub, ids[0] + "-f3", ctx), ids[0] + "-f3");
  EXPECT_EQ(resolve_job_id(*stub, "no-such-job", ctx), "no-such-job");
  EXPECT_EQ(resolve_job_id(*stub, "", ctx), "");
  std::string none = "0000000000";  // ten hex digits no random id starts with (1 in 2^40)
  EXPECT_THROW(resolve_job_id(*stub, none, ctx), FarmError);
}

}  // namespace
}  // namespace tessera
