// The worker against a fake coordinator in this process (fake_coordinator.h): what it asks
// for, what it renders, what it sends and gives back, without gRPC or another process.
// Heartbeats come every 50 ms and back-off starts at 0.1 s, so no test takes long.
#include "worker/worker.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <thread>

#include "core/io/files.h"
#include "core/scene/load.h"
#include "scene_bundle.h"
#include "tests/core/test_paths.h"
#include "tests/worker/fake_coordinator.h"
#include "wire.h"
#include "worker/scene_cache.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::FakeCoordinator;

const std::string kScene = testing::source_path("scenes/cornell-spheres.dae");
using testing::bundle_of;

class WorkerTest : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_worker_" + std::to_string(::getpid()) + "_" +
                                              ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::shared_ptr<FakeCoordinator> fake = std::make_shared<FakeCoordinator>();
  std::atomic<bool> stop{false};
  std::thread thread;
  bool returned = false;  // run()'s answer
  uint64_t tasks_done = 0;
  std::string hash;
  RenderSettings settings;

  void SetUp() override {
    const v1::SceneBundle bundle = bundle_of(kScene, &hash);
    fake->scenes[hash] = bundle;
    settings.camera.width = 32;
    settings.camera.height = 24;
    settings.max_depth = 4;
    settings.seed = 7;
  }
  void TearDown() override {
    if (thread.joinable()) finish();
    fs::remove_all(dir);
  }
  WorkerOptions options(int threads = 2) const {
    WorkerOptions o;
    o.threads = threads;
    o.cache_dir = (dir / "cache").string();
    o.name = "test-worker";
    return o;
  }
  void start(const WorkerOptions& o) {
    thread = std::thread([this, o] {
      Worker w(o, fake);
      returned = w.run(stop);
      tasks_done = w.tasks_done();
    });
  }
  // Stops the worker as SIGTERM does and waits for it; run()'s answer.
  bool finish() {
    stop = true;
    thread.join();
    return returned;
  }
  v1::Task task(uint64_t id, Rect tile, uint32_t s0, uint32_t s1, const std::string& active = "") const {
    v1::Task t;
    t.set_task_id(id);
    t.set_job_id("job");
    t.set_scene_hash(hash);
    *t.mutable_settings() = to_proto(settings);
    *t.mutable_tile() = to_proto(tile);
    t.set_sample_begin(s0);
    t.set_sample_end(s1);
    t.set_active(active);
    return t;
  }
  // A task that takes seconds at least: it is still rendering when a test acts on it.
  v1::Task huge_task(uint64_t id) const { return task(id, {0, 0, 32, 24}, 0, 1 << 14); }
};

bool same_bits(const PixelSums& a, const PixelSums& b) {
  return a.r == b.r && a.g == b.g && a.b == b.b && a.lum2 == b.lum2 && a.n == b.n;
}

TEST_F(WorkerTest, RegistersAndRendersTasksBitForBitAsTileRendererDoes) {
  std::string mask(16 * 16, '\1');
  for (size_t i = 0; i < mask.size(); i += 3) mask[i] = 0;  // some pixels converged
  const std::vector<v1::Task> tasks = {task(11, {0, 0, 16, 8}, 0, 4), task(12, {16, 8, 16, 16}, 4, 12, mask)};
  fake->task_batches.push_back(tasks);
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->results.size() == 2; }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(tasks_done, 2u);

  ASSERT_EQ(fake->registrations.size(), 1u);
  EXPECT_EQ(fake->registrations[0].version(), kProtocolVersion);
  EXPECT_EQ(fake->registrations[0].name(), "test-worker");
  EXPECT_EQ(fake->registrations[0].threads(), 2u);
  EXPECT_EQ(fake->scene_fetches, 1);  // one scene for both tasks
  EXPECT_EQ(fake->unregisters, 1);
  EXPECT_TRUE(fake->releases.empty());

  // The sums are those of the local renderer, bit for bit, and so are the light paths'
  // splat records (the scene has glass and mirror spheres: traced by default), gathered
  // from the task's rows on two threads.
  const Scene scene = load_scene(kScene);
  const TileRenderer renderer(scene, settings);
  ASSERT_TRUE(renderer.light_tracing());
  for (const v1::Task& t : tasks) {
    const v1::TaskResult* r = fake->result_for(t.task_id());
    ASSERT_NE(r, nullptr) << t.task_id();
    const Rect rect = from_proto(t.tile());
    TileStats stats;
    std::vector<SplatRecord> splats;
    const std::vector<PixelSums> local =
        renderer.render_passes(rect, {{t.sample_begin(), t.sample_end()}}, nullptr,
                               t.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(t.active().data()),
                               &stats, nullptr, nullptr, &splats);
    SplatLimits limits;
    limits.records = 1;
    limits.area = uint64_t(settings.effective_window().area());
    limits.planes = settings.sum_planes();
    limits.max_paths = uint64_t(rect.area()) * settings.spp;
    limits.max_splats_per_path = uint64_t(settings.max_depth);
    ASSERT_FALSE(r->splats_zstd().empty());
    EXPECT_EQ(decode_splats(r->splats_zstd(), limits), splats) << "task " << t.task_id();
    EXPECT_GT(splats.at(0).paths, 0u);  // (a few tiny tasks: their paths need not land in the frame)
    EXPECT_EQ(r->worker_id(), 1u);
    EXPECT_EQ(r->raw_size(), rect.area() * kBytesPerPixel);
    EXPECT_EQ(r->samples(), stats.samples);
    const std::vector<PixelSums> farm = decode_sums(r->sums_zstd(), size_t(rect.area()));
    int differ = 0;
    for (size_t i = 0; i < local.size(); ++i) differ += !same_bits(local[i], farm[i]);
    EXPECT_EQ(differ, 0) << "task " << t.task_id();
  }
  for (const auto& [id, secret] : fake->batch_identities) {  // each batch says whose it is (issue 23)
    EXPECT_EQ(id, 1u);
    EXPECT_EQ(secret, "secret-1");
  }
}

TEST_F(WorkerTest, AHeartbeatRefusalDropsTheTaskWhichIsNeverSubmitted) {
  fake->refuse = {21};
  fake->task_batches.push_back({huge_task(21)});
  fake->unregister_status = grpc::Status(grpc::StatusCode::UNAVAILABLE, "gone");  // leftovers: released
  start(options());
  size_t asked = 0;  // GetTask calls until the refusal
  ASSERT_TRUE(fake->wait_until([&] {
    for (const v1::HeartbeatRequest& hb : fake->heartbeats)
      if (hb.task_ids_size() == 1 && hb.task_ids(0) == 21) return (asked = fake->task_requests.size()) > 0;
    return false;
  }));
  // Dropped, the task no longer fills the queue: the fetcher asks for work again, and
  // renders what it gets.
  ASSERT_TRUE(fake->wait_until([&] { return fake->task_requests.size() > asked; }));
  fake->set([&] { fake->task_batches.push_back({task(22, {0, 0, 8, 8}, 0, 2)}); });
  ASSERT_TRUE(fake->wait_until([&] { return fake->result_for(22) != nullptr; }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(fake->result_for(21), nullptr);
  EXPECT_TRUE(fake->releases.empty());  // refused, so not the worker's to give back
  for (size_t i = 0; i < fake->heartbeats.size(); ++i)
    if (fake->heartbeats[i].task_ids_size() == 1 && fake->heartbeats[i].task_ids(0) == 21) {
      for (size_t j = i + 1; j < fake->heartbeats.size(); ++j)  // never renewed again
        for (uint64_t id : fake->heartbeats[j].task_ids()) EXPECT_NE(id, 21u);
      break;
    }
}

TEST_F(WorkerTest, OnStopUnfinishedLeasesAreReleasedAndFinishedResultsSent) {
  fake->task_batches.push_back({task(31, {0, 0, 4, 1}, 0, 1), task(32, {4, 0, 4, 1}, 0, 1)});
  fake->task_batches.push_back({huge_task(33)});
  fake->hold_submissions = true;  // the first results are still on their way at the stop
  fake->unregister_status = grpc::Status(grpc::StatusCode::UNAVAILABLE, "gone");
  start(options(1));
  ASSERT_TRUE(fake->wait_until([&] {  // 31 and 32 rendered and on their way, 33 being rendered
    const auto sent = [&](uint64_t id) {
      return std::find(fake->submitted_ids.begin(), fake->submitted_ids.end(), id) != fake->submitted_ids.end();
    };
    return sent(31) && sent(32) && fake->handed_out.size() == 3;
  }));
  stop = true;
  fake->set([&] { fake->hold_submissions = false; });
  EXPECT_TRUE(finish());
  EXPECT_NE(fake->result_for(31), nullptr);
  EXPECT_NE(fake->result_for(32), nullptr);
  EXPECT_EQ(fake->result_for(33), nullptr);
  EXPECT_EQ(tasks_done, 2u);
  EXPECT_EQ(fake->unregisters, 1);
  // Unregistering failed, so the unfinished lease goes back by itself.
  ASSERT_EQ(fake->releases.size(), 1u);
  EXPECT_EQ(fake->releases[0].task_id(), 33u);
  EXPECT_EQ(fake->releases[0].error(), "");
}

TEST_F(WorkerTest, OnStopAnUnregisteredWorkerLeavesItsLeasesToTheCoordinator) {
  fake->task_batches.push_back({huge_task(34)});
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->handed_out.size() == 1; }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(fake->unregisters, 1);  // which gives back every lease at once
  EXPECT_TRUE(fake->releases.empty());
  EXPECT_TRUE(fake->results.empty());
}

TEST_F(WorkerTest, AnUnreachableCoordinatorIsRetriedWithBackOffAndAForgottenWorkerRegistersAgain) {
  const grpc::Status down(grpc::StatusCode::UNAVAILABLE, "connection refused");
  fake->register_failures = {down, down};
  fake->get_task_failures = {grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "unknown worker 1; register again")};
  start(options());
  ASSERT_TRUE(fake->wait_until([&] {
    for (const v1::GetTaskRequest& r : fake->task_requests)
      if (r.worker_id() == 2) return true;
    return false;
  }));
  EXPECT_TRUE(finish());
  ASSERT_EQ(fake->register_times.size(), 4u);  // down, down, registered as 1, then as 2
  const auto gap = [&](int i) {
    return std::chrono::duration<double>(fake->register_times[i + 1] - fake->register_times[i]).count();
  };
  EXPECT_GE(gap(0), 0.1);  // the first back-off
  EXPECT_GE(gap(1), 0.2);  // doubled
  EXPECT_GE(gap(2), 0.1);  // reset by the registration, then waited after "unknown worker"
  ASSERT_EQ(fake->registrations.size(), 2u);
  EXPECT_EQ(fake->task_requests[0].worker_id(), 1u);
  // Every request carries the secret of the registration its id came from (issue 23).
  for (const v1::GetTaskRequest& r : fake->task_requests)
    EXPECT_EQ(r.worker_secret(), "secret-" + std::to_string(r.worker_id()));
}

TEST_F(WorkerTest, ARefusedWorkerStopsAtOnce) {
  fake->register_failures = {grpc::Status(grpc::StatusCode::PERMISSION_DENIED, "a client token may not register")};
  start(options());
  thread.join();
  EXPECT_FALSE(returned);
  EXPECT_EQ(fake->register_times.size(), 1u);  // retrying cannot help
  EXPECT_TRUE(fake->task_requests.empty());
}

// With an enrolment token the worker enrols under its name before registering, and again
// when the coordinator no longer knows its credential (unused for an hour, or its name
// enrolled again); a refusal of a credential it was just given is final.
TEST_F(WorkerTest, AnEnrollingWorkerEnrolsThenRegistersAndEnrolsAgainWhenItsCredentialIsUnknown) {
  WorkerOptions o = options();
  o.enrol_token = "enrol-token-0123456789";
  o.name = "render-7";
  start(o);
  ASSERT_TRUE(fake->wait_until([&] { return !fake->registrations.empty(); }));
  // The coordinator forgets the worker and then its credential (unused for an hour): told
  // to register again, it is refused as unknown, enrols again, and registers.
  fake->set([&] {
    fake->get_task_failures = {grpc::Status(grpc::StatusCode::FAILED_PRECONDITION, "unknown worker 1")};
    fake->register_failures = {grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "the access token is not known")};
  });
  ASSERT_TRUE(fake->wait_until([&] { return fake->registrations.size() == 2; }));
  EXPECT_TRUE(finish());
  ASSERT_EQ(fake->enrolments.size(), 2u);
  EXPECT_EQ(fake->enrolments[0].name(), "render-7");
  EXPECT_EQ(fake->register_times.size(), 3u);  // registered, refused (stale), registered

  // A credential refused right after it was made: final, no loop of enrolments.
  stop = false;
  fake = std::make_shared<FakeCoordinator>();
  fake->register_failures = {grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "not known")};
  start(o);
  thread.join();
  EXPECT_FALSE(returned);
  EXPECT_EQ(fake->enrolments.size(), 1u);

  // Enrolment refused (a quarantined name): the worker stops at once.
  stop = false;
  fake = std::make_shared<FakeCoordinator>();
  fake->enrol_failures = {grpc::Status(grpc::StatusCode::PERMISSION_DENIED, "worker 'render-7' is quarantined")};
  start(o);
  thread.join();
  EXPECT_FALSE(returned);
  EXPECT_EQ(fake->enrolments.size(), 1u);
  EXPECT_TRUE(fake->register_times.empty());
}

TEST_F(WorkerTest, ItAsksForTwoTasksThenForItsLookaheadOnceItsSpeedIsMeasured) {
  WorkerOptions o = options();
  o.max_tasks = 8;
  fake->task_batches.push_back({task(51, {0, 0, 16, 16}, 0, 4)});
  start(o);
  size_t measured = 0;  // requests before the result (and so its speed) was known
  ASSERT_TRUE(fake->wait_until([&] {
    measured = fake->task_requests.size();
    return fake->result_for(51) != nullptr;
  }));
  ASSERT_TRUE(fake->wait_until([&] { return fake->task_requests.size() > measured; }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(fake->task_requests[0].max_tasks(), 2u);  // no speed yet
  EXPECT_EQ(fake->task_requests[0].max_samples(), 0u);
  const v1::GetTaskRequest& later = fake->task_requests[measured];
  EXPECT_GE(later.max_tasks(), 7u);    // its room: 8 leases, less the one not yet sent
  EXPECT_GT(later.max_samples(), 0u);  // the lookahead at its speed
}

// A dropped connection or a stalled link (UNAVAILABLE) well within the lease time keeps the
// registration and the work held: the coordinator still holds those leases.
TEST_F(WorkerTest, ALinkBlipKeepsTheRegistrationAndTheWorkHeld) {
  fake->task_batches.push_back({task(81, {0, 0, 16, 16}, 0, 4), task(82, {0, 16, 16, 8}, 0, 4)});
  fake->hold_submissions = true;  // 81 and 82 stay held while the link blips
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->handed_out.size() == 2; }));
  ASSERT_TRUE(fake->wait_until([&] { return fake->submissions > 0; }));  // both rendered, none sent
  size_t failed = 0;                                                     // the request that fails
  fake->set([&] {
    failed = fake->task_requests.size();
    fake->get_task_failures = {grpc::Status(grpc::StatusCode::UNAVAILABLE, "Socket closed")};
  });
  ASSERT_TRUE(fake->wait_until([&] { return fake->task_requests.size() >= failed + 3; }));  // and asked again
  fake->set([&] { fake->hold_submissions = false; });
  ASSERT_TRUE(fake->wait_until([&] { return fake->result_for(81) && fake->result_for(82); }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(fake->registrations.size(), 1u);
  for (size_t i = failed; i < fake->task_requests.size(); ++i) EXPECT_EQ(fake->task_requests[i].worker_id(), 1u) << i;
  EXPECT_EQ(fake->result_for(81)->worker_id(), 1u);
  EXPECT_EQ(fake->result_for(82)->worker_id(), 1u);
  EXPECT_TRUE(fake->releases.empty());
}

TEST_F(WorkerTest, ItAsksForNoMoreThanTheCoordinatorsBound) {
  fake->max_leases = 3;
  fake->task_batches.push_back({task(71, {0, 0, 16, 16}, 0, 4)});
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->result_for(71) != nullptr && fake->task_requests.size() >= 2; }));
  EXPECT_TRUE(finish());
  for (const v1::GetTaskRequest& r : fake->task_requests) EXPECT_LE(r.max_tasks(), 3u);
}

TEST_F(WorkerTest, ATaskWhoseSceneCannotLoadIsReleasedWithTheError) {
  v1::SceneBundle broken;
  broken.set_main_file("broken.dae");
  v1::SceneFile* f = broken.add_files();
  f->set_path("broken.dae");
  f->set_content("<COLLADA><asset><up_axis>Q_UP</up_axis></asset></COLLADA>");
  const std::string broken_hash = bundle_hash(broken.main_file(), broken.files());
  fake->scenes[broken_hash] = broken;
  v1::Task bad = task(61, {0, 0, 8, 8}, 0, 1), missing = task(62, {0, 0, 8, 8}, 0, 1);
  bad.set_scene_hash(broken_hash);
  missing.set_scene_hash(std::string(32, 'f'));  // the coordinator has no such scene
  fake->task_batches.push_back({bad, missing});
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->releases.size() == 2; }));
  EXPECT_TRUE(finish());
  EXPECT_EQ(fake->releases[0].task_id(), 61u);
  EXPECT_NE(fake->releases[0].error().find("broken.dae"), std::string::npos) << fake->releases[0].error();
  EXPECT_NE(fake->releases[0].error().find("Q_UP"), std::string::npos) << fake->releases[0].error();
  EXPECT_EQ(fake->releases[1].task_id(), 62u);
  EXPECT_NE(fake->releases[1].error().find("fetch scene " + std::string(32, 'f')), std::string::npos)
      << fake->releases[1].error();
  EXPECT_EQ(fake->releases[0].worker_id(), 1u);
  EXPECT_EQ(fake->releases[0].worker_secret(), "secret-1");
  EXPECT_TRUE(fake->results.empty());
}

// Found by audit: a task's tile was taken as sent (a 65536-pixel square asked for 160 GiB of
// sums, outside the try that releases a task: the worker hung). One outside the frame's
// window, or larger than its tile size, is released naming the problem.
TEST_F(WorkerTest, ATileThatIsNotOneOfTheFramesIsReleasedNamingIt) {
  const Rect window = settings.effective_window();
  fake->task_batches.push_back({task(71, {window.w - 4, 0, 8, 8}, 0, 1),
                                task(72, {0, 0, settings.tile_size + 1, 1}, 0, 1), task(73, {0, 0, 8, 8}, 0, 1)});
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->releases.size() == 2 && fake->results.size() == 1; }));
  EXPECT_TRUE(finish());
  for (const v1::ReleaseRequest& r : fake->releases)
    EXPECT_NE(r.error().find("is not a tile of the frame's " + std::to_string(window.w) + "x" +
                             std::to_string(window.h) + " window"),
              std::string::npos)
        << r.error();
}

// A coordinator at its bound of open scene downloads (RESOURCE_EXHAUSTED) is busy, not
// broken: the fetch tries again, and after its attempts gives the task back without an
// error (an error would count as the task failing, and two fail its job); the next lease
// of the scene's tasks renders once the downloads are let through.
TEST_F(WorkerTest, ABusyCoordinatorsSceneDownloadGivesTheTaskBackWithoutAFailure) {
  fake->scene_streams_busy = worker::SceneCache::kFetchAttempts + 1;
  fake->task_batches.push_back({task(63, {0, 0, 8, 8}, 0, 1)});
  fake->task_batches.push_back({task(64, {0, 0, 8, 8}, 0, 1)});
  start(options());
  ASSERT_TRUE(fake->wait_until([&] { return fake->result_for(64) != nullptr; }));
  EXPECT_TRUE(finish());
  ASSERT_EQ(fake->releases.size(), 1u);
  EXPECT_EQ(fake->releases[0].task_id(), 63u);
  EXPECT_EQ(fake->releases[0].error(), "");
  EXPECT_EQ(fake->scene_fetches, worker::SceneCache::kFetchAttempts + 2);  // 4 refused, then 1 refused and 1 whole
}

}  // namespace
}  // namespace tessera
