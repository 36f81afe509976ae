// A coordinator in the test's process, behind the worker's stub interface: it hands out the
// tasks a test queues, answers the other calls as the test says, and records every call.
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "scene_bundle.h"
#include "tessera.grpc.pb.h"

namespace tessera::testing {

class FakeCoordinator : public v1::TesseraWorker::StubInterface {
 public:
  using Clock = std::chrono::steady_clock;

  // What the test sets (under mu, or before the worker starts) ...
  std::deque<grpc::Status> register_failures;  // answers before Register succeeds
  std::deque<grpc::Status> enrol_failures;     // answers before Enrol succeeds
  uint32_t heartbeat_interval_ms = 50;
  uint32_t max_leases = 0;                         // RegisterResponse.max_leases (0: as coordinators before it)
  std::deque<std::vector<v1::Task>> task_batches;  // GetTask: the front batch, up to max_tasks
  std::deque<grpc::Status> get_task_failures;      // answers before GetTask works again
  std::map<std::string, v1::SceneBundle> scenes;   // FetchSceneChunks, by hash
  size_t scene_chunk_bytes = 1000;                 // the pieces it sends them in
  // The next `scene_streams_to_cut` scene streams break after `cut_after_pieces` pieces
  // each (UNAVAILABLE), as a lost connection would.
  int scene_streams_to_cut = 0;
  int cut_after_pieces = 2;
  int scene_streams_busy = 0;  // the next ones are refused (RESOURCE_EXHAUSTED), as a busy coordinator does
  bool damage_scenes = false;  // a byte of every piece flipped: bytes that do not hash to the scene's hash
  std::set<uint64_t> refuse;   // Heartbeat refuses these tasks
  grpc::Status unregister_status;
  bool hold_submissions = false;  // SubmitResults waits until this is false again

  // ... and what the worker did.
  std::vector<v1::RegisterRequest> registrations;
  std::vector<v1::EnrolRequest> enrolments;       // every Enrol call, failed or not
  std::vector<Clock::time_point> register_times;  // of every Register call, failed or not
  std::vector<v1::GetTaskRequest> task_requests;
  std::vector<uint64_t> handed_out;  // task ids, in order
  int scene_fetches = 0;
  std::vector<v1::FetchSceneRequest> scene_requests;
  std::vector<v1::HeartbeatRequest> heartbeats;
  std::vector<v1::TaskResult> results;
  int submissions = 0;                                             // SubmitResults calls begun
  std::vector<uint64_t> submitted_ids;                             // their results' tasks, held or not
  std::vector<std::pair<uint64_t, std::string>> batch_identities;  // each result batch's worker id and secret
  std::vector<v1::ReleaseRequest> releases;
  int unregisters = 0;

  std::mutex mu;

  // Waits up to 10 s for `done` (called under mu); whether it came true.
  bool wait_until(const std::function<bool()>& done) {
    std::unique_lock<std::mutex> lock(mu);
    return changed_.wait_for(lock, std::chrono::seconds(10), done);
  }
  // Changes the test's settings under the lock and wakes waiting calls.
  void set(const std::function<void()>& change) {
    std::lock_guard<std::mutex> lock(mu);
    change();
    changed_.notify_all();
  }
  const v1::TaskResult* result_for(uint64_t task_id) {
    for (const v1::TaskResult& r : results)
      if (r.task_id() == task_id) return &r;
    return nullptr;
  }

  grpc::Status Enrol(grpc::ClientContext*, const v1::EnrolRequest& req, v1::EnrolResponse* resp) override {
    std::lock_guard<std::mutex> lock(mu);
    enrolments.push_back(req);
    changed_.notify_all();
    if (!enrol_failures.empty()) {
      const grpc::Status st = enrol_failures.front();
      enrol_failures.pop_front();
      return st;
    }
    resp->set_credential("credential-" + std::to_string(enrolments.size()));
    return grpc::Status::OK;
  }

  grpc::Status Register(grpc::ClientContext*, const v1::RegisterRequest& req, v1::RegisterResponse* resp) override {
    std::lock_guard<std::mutex> lock(mu);
    register_times.push_back(Clock::now());
    changed_.notify_all();
    if (!register_failures.empty()) {
      const grpc::Status st = register_failures.front();
      register_failures.pop_front();
      return st;
    }
    registrations.push_back(req);
    resp->set_worker_id(registrations.size());  // a new id each time, with its secret
    resp->set_worker_secret("secret-" + std::to_string(registrations.size()));
    resp->set_heartbeat_interval_ms(heartbeat_interval_ms);
    resp->set_lease_ms(10 * heartbeat_interval_ms);
    resp->set_max_leases(max_leases);
    return grpc::Status::OK;
  }

  grpc::Status GetTask(grpc::ClientContext*, const v1::GetTaskRequest& req, v1::GetTaskResponse* resp) override {
    std::unique_lock<std::mutex> lock(mu);
    task_requests.push_back(req);
    changed_.notify_all();
    if (!get_task_failures.empty()) {
      const grpc::Status st = get_task_failures.front();
      get_task_failures.pop_front();
      return st;
    }
    if (task_batches.empty()) {  // no work: a short long-poll
      changed_.wait_for(lock, std::chrono::milliseconds(10));
      return grpc::Status::OK;
    }
    std::vector<v1::Task>& batch = task_batches.front();
    const size_t n = std::min<size_t>(batch.size(), std::max(1u, req.max_tasks()));
    for (size_t i = 0; i < n; ++i) {
      *resp->add_tasks() = batch[i];
      handed_out.push_back(batch[i].task_id());
    }
    batch.erase(batch.begin(), batch.begin() + ptrdiff_t(n));
    if (batch.empty()) task_batches.pop_front();
    return grpc::Status::OK;
  }

  // A server stream of messages made in advance, then its status.
  class Stream : public grpc::ClientReaderInterface<v1::SceneChunk> {
   public:
    Stream(std::deque<v1::SceneChunk> chunks, grpc::Status end) : chunks_(std::move(chunks)), end_(std::move(end)) {}
    bool Read(v1::SceneChunk* msg) override {
      if (chunks_.empty()) return false;
      *msg = std::move(chunks_.front());
      chunks_.pop_front();
      return true;
    }
    bool NextMessageSize(uint32_t* sz) override {
      *sz = chunks_.empty() ? 0 : uint32_t(chunks_.front().ByteSizeLong());
      return !chunks_.empty();
    }
    grpc::Status Finish() override { return end_; }
    void WaitForInitialMetadata() override {}

   private:
    std::deque<v1::SceneChunk> chunks_;
    grpc::Status end_;
  };

  grpc::ClientReaderInterface<v1::SceneChunk>* FetchSceneChunksRaw(grpc::ClientContext*,
                                                                   const v1::FetchSceneRequest& req) override {
    std::lock_guard<std::mutex> lock(mu);
    ++scene_fetches;
    scene_requests.push_back(req);
    if (scene_streams_busy > 0) {
      --scene_streams_busy;
      return new Stream({},
                        grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                     "64 open streams (scene downloads) per caller at most (--max-streams-per-peer)"));
    }
    const auto it = scenes.find(req.scene_hash());
    if (it == scenes.end())
      return new Stream({}, grpc::Status(grpc::StatusCode::NOT_FOUND, "no scene " + req.scene_hash()));
    const v1::SceneBundle& b = it->second;
    std::deque<v1::SceneChunk> out(1);
    v1::SceneManifest* m = out[0].mutable_manifest();
    m->set_main_file(b.main_file());
    m->set_scene_hash(bundle_hash(b.main_file(), b.files()));
    for (const v1::SceneFile& f : b.files()) {
      v1::SceneFileInfo* info = m->add_files();
      info->set_path(f.path());
      info->set_size(f.content().size());
    }
    for (uint32_t i = req.file(); i < uint32_t(b.files_size()); ++i)
      for (uint64_t at = i == req.file() ? req.offset() : 0; at < b.files(int(i)).content().size();
           at += scene_chunk_bytes) {
        v1::SceneChunk& piece = out.emplace_back();
        piece.set_file(i);
        piece.set_offset(at);
        piece.set_data(b.files(int(i)).content().substr(at, scene_chunk_bytes));
        if (damage_scenes) (*piece.mutable_data())[0] ^= 1;
      }
    grpc::Status end;
    if (scene_streams_to_cut > 0) {
      --scene_streams_to_cut;
      out.resize(std::min<size_t>(out.size(), size_t(1 + cut_after_pieces)));
      end = grpc::Status(grpc::StatusCode::UNAVAILABLE, "connection lost (a test's)");
    }
    return new Stream(std::move(out), end);
  }

  grpc::Status Heartbeat(grpc::ClientContext*, const v1::HeartbeatRequest& req, v1::HeartbeatResponse* resp) override {
    std::lock_guard<std::mutex> lock(mu);
    heartbeats.push_back(req);
    for (uint64_t id : req.task_ids())
      if (refuse.count(id)) resp->add_refused(id);
    changed_.notify_all();
    return grpc::Status::OK;
  }

  grpc::Status SubmitResults(grpc::ClientContext*, const v1::ResultBatch& req, v1::ResultAcks* resp) override {
    std::unique_lock<std::mutex> lock(mu);
    ++submissions;
    for (const v1::TaskResult& r : req.results()) submitted_ids.push_back(r.task_id());
    changed_.notify_all();
    changed_.wait(lock, [this] { return !hold_submissions; });
    batch_identities.emplace_back(req.worker_id(), req.worker_secret());
    for (const v1::TaskResult& r : req.results()) {
      results.push_back(r);
      resp->add_acks()->set_accepted(true);
    }
    changed_.notify_all();
    return grpc::Status::OK;
  }

  grpc::Status ReleaseTask(grpc::ClientContext*, const v1::ReleaseRequest& req, v1::ReleaseResponse*) override {
    std::lock_guard<std::mutex> lock(mu);
    releases.push_back(req);
    changed_.notify_all();
    return grpc::Status::OK;
  }

  grpc::Status Unregister(grpc::ClientContext*, const v1::UnregisterRequest&, v1::UnregisterResponse*) override {
    std::lock_guard<std::mutex> lock(mu);
    ++unregisters;
    changed_.notify_all();
    return unregister_status;
  }

 private:
  std::condition_variable changed_;

  // The worker makes only blocking calls.
#define TESSERA_NO_ASYNC(Rpc, Request, Response)                                                                    \
  grpc::ClientAsyncResponseReaderInterface<v1::Response>* Async##Rpc##Raw(grpc::ClientContext*, const v1::Request&, \
                                                                          grpc::CompletionQueue*) override {        \
    return nullptr;                                                                                                 \
  }                                                                                                                 \
  grpc::ClientAsyncResponseReaderInterface<v1::Response>* PrepareAsync##Rpc##Raw(                                   \
      grpc::ClientContext*, const v1::Request&, grpc::CompletionQueue*) override {                                  \
    return nullptr;                                                                                                 \
  }
  TESSERA_NO_ASYNC(Enrol, EnrolRequest, EnrolResponse)
  TESSERA_NO_ASYNC(Register, RegisterRequest, RegisterResponse)
  TESSERA_NO_ASYNC(GetTask, GetTaskRequest, GetTaskResponse)
  TESSERA_NO_ASYNC(Heartbeat, HeartbeatRequest, HeartbeatResponse)
  TESSERA_NO_ASYNC(SubmitResults, ResultBatch, ResultAcks)
  TESSERA_NO_ASYNC(ReleaseTask, ReleaseRequest, ReleaseResponse)
  TESSERA_NO_ASYNC(Unregister, UnregisterRequest, UnregisterResponse)
#undef TESSERA_NO_ASYNC
  grpc::ClientAsyncReaderInterface<v1::SceneChunk>* AsyncFetchSceneChunksRaw(grpc::ClientContext*,
                                                                             const v1::FetchSceneRequest&,
                                                                             grpc::CompletionQueue*, void*) override {
    return nullptr;
  }
  grpc::ClientAsyncReaderInterface<v1::SceneChunk>* PrepareAsyncFetchSceneChunksRaw(grpc::ClientContext*,
                                                                                    const v1::FetchSceneRequest&,
                                                                                    grpc::CompletionQueue*) override {
    return nullptr;
  }
};

// A scene file and what it references, as a bundle; its content hash in *hash.
inline v1::SceneBundle bundle_of(const std::string& path, std::string* hash) {
  v1::SceneBundle b;
  std::string main;
  pack_scene(path, &main, b.mutable_files());
  b.set_main_file(main);
  *hash = bundle_hash(b.main_file(), b.files());
  return b;
}

}  // namespace tessera::testing
