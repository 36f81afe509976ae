// The coordinator's bounds: batched leases, fair shares, live jobs, pixels, scene bytes and
// samples per client, registered workers, results only from the lease holder.
#include <atomic>
#include <set>
#include <sstream>
#include <thread>

#include "server/metrics.h"
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

TEST_F(CoordinatorTest, BatchedLeasesFollowTheCountAndSampleLimits) {
  const RenderSettings s = job_settings();  // 48x36 in 16-pixel tiles: 9 tiles, passes of 4, 4, 2
  const std::string id = c->submit(request(s));
  const uint64_t w = worker();
  EXPECT_EQ(c->get_task(w, 3).tasks_size(), 3);
  // 16 x 16 pixels x 4 samples = 1024 samples a task: a budget of 1500 takes two.
  EXPECT_EQ(c->get_task(w, 100, 1500).tasks_size(), 2);
  const v1::GetTaskResponse rest = c->get_task(w, 100);
  EXPECT_EQ(rest.tasks_size(), 4);  // every tile's first pass is out: nothing else is ready
  EXPECT_EQ(c->heartbeat(w, std::vector<uint64_t>{rest.tasks(0).task_id(), 999999}),
            std::vector<uint64_t>{999999});  // renewed, and refused the unknown one
  for (const v1::Task& t : rest.tasks()) ASSERT_TRUE(c->submit_result(render_task(t, w)).accepted());
  for (v1::GetTaskResponse r = c->get_task(w, 100); r.tasks_size() > 0; r = c->get_task(w, 100))
    for (const v1::Task& t : r.tasks()) ASSERT_TRUE(c->submit_result(render_task(t, w)).accepted());
  EXPECT_NE(c->status(id, false).state(), v1::JobStatus::DONE);  // the first five were never returned
  t += 10;                                                       // their leases expire and the tiles go out again
  drain(w);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// A small frame has fewer tasks than eager workers would queue: each gets its share by
// threads, so the first to ask does not take everything while the others idle.
TEST_F(CoordinatorTest, WorkersGetTheirShareOfTheReadyWorkByThreads) {
  c->submit(request(job_settings()));  // 9 tiles: 9 tasks ready at first
  auto join = [&](uint32_t threads) {
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name("w");
    r.set_threads(threads);
    return c->register_worker(r).worker_id();
  };
  const uint64_t big = join(2), small = join(1);
  const v1::GetTaskResponse a = c->get_task(big, 100);
  EXPECT_EQ(a.tasks_size(), 6);                      // 2 of 3 threads: 6 of 9
  EXPECT_EQ(c->get_task(big, 100).tasks_size(), 0);  // it holds its share already
  EXPECT_EQ(c->get_task(small, 100).tasks_size(), 3);
  // As results come back, the work there is shrinks, and so do the shares; a worker with
  // nothing always gets at least one task.
  for (const v1::Task& task : a.tasks()) ASSERT_TRUE(c->submit_result(render_task(task, big)).accepted());
  EXPECT_EQ(c->get_task(big, 100).tasks_size(), 6);
  // A claimed thread count is bounded: it only weighs shares.
  const uint64_t liar = join(4000000000u);
  for (const WorkerInfo& info : c->workers()) {
    if (info.id == liar) {
      EXPECT_EQ(info.threads, WorkerRegistry::kMaxThreads);
    }
  }
}

// Per-client and memory limits refuse a job before anything large is allocated, with a
// message that names the limit; ending jobs makes room again.
TEST_F(CoordinatorTest, LiveJobsPerClientAndLivePixelsAreBounded) {
  CoordinatorOptions o = options();
  o.max_jobs_per_client = 2;
  o.max_live_pixels = 4 * live_pixels_of(job_settings());  // four of job_settings()'s frames
  c.reset();                                               // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const std::string a1 = c->submit(request(job_settings()), "alice");
  c->submit(request(job_settings()), "alice");
  try {
    c->submit(request(job_settings()), "alice");
    ADD_FAILURE() << "a third live job for alice";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_NE(std::string(e.what()).find("--max-jobs-per-client"), std::string::npos) << e.what();
  }
  c->submit(request(job_settings()), "bob");  // others are not held back by alice
  c->cancel(a1, "alice", false);
  c->submit(request(job_settings()), "alice");  // a live job ended: room again
  RenderSettings big = job_settings();
  big.camera.width = 96;  // two frames' worth: 4 live frames already
  try {
    c->submit(request(big), "carol");
    ADD_FAILURE() << "past the live pixel limit";
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("--max-live-pixels"), std::string::npos) << e.what();
  }
  EXPECT_EQ(c->list().size(), 4u);  // nothing was kept of the refused ones
}

// Found by review: a submit's limits were checked, then its scene checked outside the lock,
// then the job added, so submits racing each other all passed (32 parallel ones under a
// limit of 2 were accepted). Admitted submits now hold their place while they work.
TEST_F(CoordinatorTest, ParallelSubmitsNeverPassTheLimitsTogether) {
  CoordinatorOptions o = options();
  o.max_jobs_per_client = 2;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  std::atomic<int> accepted{0}, refused{0};
  std::vector<std::thread> clients;
  for (int i = 0; i < 12; ++i)
    clients.emplace_back([&] {
      try {
        c->submit(request(job_settings()), "alice");
        ++accepted;
      } catch (const RequestError& e) {
        EXPECT_NE(std::string(e.what()).find("--max-jobs-per-client"), std::string::npos) << e.what();
        ++refused;
      }
    });
  for (std::thread& th : clients) th.join();
  EXPECT_EQ(accepted.load(), 2);
  EXPECT_EQ(refused.load(), 10);
  EXPECT_EQ(c->list().size(), 2u);
  c->submit(request(job_settings()), "bob");  // nothing of alice's refused ones is held
}

// Found by review: a requeue took no limit at all, so a client could cancel and requeue its
// way to any number of live jobs and films (and a restart restored them all). It is bounded
// as a submit is, by the owner's limits; refused, the job stays as it was.
TEST_F(CoordinatorTest, ARequeueIsBoundedLikeASubmit) {
  CoordinatorOptions o = options();
  o.max_jobs_per_client = 2;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const std::string first = c->submit(request(job_settings()), "alice");
  c->cancel(first, "alice", false);
  ASSERT_TRUE(c->wait_for_end(first, 10));
  const std::string second = c->submit(request(job_settings()), "alice");
  c->submit(request(job_settings()), "alice");
  try {
    c->requeue(first, "admin", true);  // the owner's limits, whoever asks
    ADD_FAILURE() << "a third live job for alice by a requeue";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_NE(std::string(e.what()).find("client 'alice' has 2 live jobs"), std::string::npos) << e.what();
  }
  EXPECT_EQ(c->status(first, false).state(), v1::JobStatus::CANCELLED);
  c->cancel(second, "alice", false);
  ASSERT_TRUE(c->wait_for_end(second, 10));
  EXPECT_EQ(c->requeue(first, "alice", false).state(), v1::JobStatus::QUEUED);  // room again
}

// A frame with AOVs holds their sums beside its film (72 bytes a pixel more than the 40):
// it weighs 2.8 frames against --max-live-pixels. One that may trace light paths (on, or
// auto: the coordinator does not judge the scene) holds a splat film too (32 bytes a pixel
// and plane).
TEST_F(CoordinatorTest, AFrameWithAovsWeighsItsAovSumsAgainstTheLivePixels) {
  RenderSettings s = job_settings();
  const int64_t area = s.effective_window().area();
  for (auto mode : {RenderSettings::LightTracer::kOn, RenderSettings::LightTracer::kAuto}) {
    s.light_tracer = mode;
    EXPECT_EQ(live_pixels_of(s), area + (area * 32 + 39) / 40);
  }
  s.light_tracer = RenderSettings::LightTracer::kOff;
  EXPECT_EQ(live_pixels_of(s), area);
  s.aovs = kAovDenoising;  // half-buffers: a second film's worth of sums
  EXPECT_EQ(live_pixels_of(s), 2 * area + (area * 72 + 39) / 40);
  s.aovs = kAovAll;
  EXPECT_EQ(live_pixels_of(s), area + (area * 72 + 39) / 40);
  CoordinatorOptions o = options();
  o.max_live_pixels = 2 * area;  // two plain frames, but not one with AOVs
  c.reset();                     // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  try {
    c->submit(request(s), "alice");
    ADD_FAILURE() << "a frame with AOVs past the live pixel limit";
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("--max-live-pixels"), std::string::npos) << e.what();
  }
  s.aovs = 0;
  c->submit(request(s), "alice");
}

TEST_F(CoordinatorTest, SceneBytesAndQueuedSamplesPerClientAreBounded) {
  const v1::SubmitJobRequest one = request(job_settings());
  const uint64_t bytes = bundle_bytes(one.files());
  CoordinatorOptions o = options();
  o.max_scene_bytes_per_client = 2 * bytes;  // two jobs' scenes
  o.max_queued_samples_per_client = 3 * 48 * 36 * 10;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  c->submit(one, "alice");
  c->submit(one, "alice");
  try {
    c->submit(one, "alice");
    ADD_FAILURE() << "a third scene's bytes for alice";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_NE(std::string(e.what()).find("--max-scene-bytes-per-client"), std::string::npos) << e.what();
  }
  RenderSettings more = job_settings();
  more.spp = 40;  // four frames' samples
  try {
    c->submit(request(more), "bob");
    ADD_FAILURE() << "past bob's queued samples";
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("--max-queued-samples-per-client"), std::string::npos) << e.what();
  }
  c->submit(one, "bob");  // within both
  EXPECT_EQ(c->list().size(), 3u);
}

// An upload counts against its client's scene bytes from its manifest on, with the
// client's live jobs and its other uploads: a client cannot fill the coordinator's disk.
TEST_F(CoordinatorTest, UploadsCountAgainstTheClientsSceneBytes) {
  const v1::SubmitJobRequest one = request(job_settings());
  const uint64_t bytes = bundle_bytes(one.files());
  CoordinatorOptions o = options();
  o.max_scene_bytes_per_client = 2 * bytes;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  c->submit(one, "alice");  // a live job's scene
  const v1::SceneUpload up = upload("alice");
  try {
    upload("alice");
    ADD_FAILURE() << "a third scene's bytes for alice";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_EQ(std::string(e.what()), "client 'alice''s live jobs and uploads hold " + std::to_string(2 * bytes) +
                                         " scene bytes; this upload's " + std::to_string(bytes) +
                                         " would pass the limit of " + std::to_string(2 * bytes) +
                                         " (--max-scene-bytes-per-client)");
  }
  EXPECT_NO_THROW(upload("bob"));
  try {  // an upload is its uploader's
    c->submit(request(job_settings(), up), "bob");
    ADD_FAILURE() << "bob used alice's upload";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kNotFound);
  }
  c->submit(request(job_settings(), up), "alice");
  EXPECT_EQ(c->list().size(), 2u);
}

// Found by audit: an upload nobody submits was taken off the disk only at the next upload
// or submit, for good if none came. The reaper takes it off once past its time.
TEST_F(CoordinatorTest, AnUploadNobodySubmitsLeavesTheDiskOnTheReapersTick) {
  CoordinatorOptions o = options();
  o.upload_kept_seconds = 10;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const auto staged = [&] {
    size_t n = 0;
    for (const auto& e : fs::directory_iterator(dir + "/scenes"))
      n += e.path().filename().string().find(".staging-") != std::string::npos;
    return n;
  };
  upload("alice");
  EXPECT_EQ(staged(), 1u);
  t += 61;  // past its time, and the reaper's minute
  c->expire_leases();
  EXPECT_EQ(staged(), 0u);
}

// A worker that stops says so: its leases go back at once and it no longer counts.
TEST_F(CoordinatorTest, UnregisteredWorkersGiveTheirLeasesBackAndLeave) {
  c->submit(request(job_settings()));
  const uint64_t leaving = worker(), staying = worker();
  const v1::GetTaskResponse held = c->get_task(leaving, 3);
  ASSERT_EQ(held.tasks_size(), 3);
  c->unregister(leaving);
  EXPECT_EQ(c->workers().size(), 1u);
  EXPECT_EQ(c->counters().leases_released, 3u);
  EXPECT_THROW(c->get_task(leaving), RequestError);
  // The three tiles are ready again at once, for the worker that stays (no expiry wait).
  std::set<uint32_t> again;
  const v1::GetTaskResponse reissued = c->get_task(staying, 100);
  for (const v1::Task& t : reissued.tasks()) again.insert(t.tile().x() * 1000 + t.tile().y());
  for (const v1::Task& t : held.tasks()) EXPECT_TRUE(again.count(t.tile().x() * 1000 + t.tile().y()));
}

// Issue 10, row 7: results for tasks leased to another worker, or from a worker id that
// never registered, were merged (the honest ones then dropped as duplicates). A result
// counts only from the worker that holds, or held, the task's lease.
TEST_F(CoordinatorTest, ResultsCountOnlyFromTheLeaseHolder) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const uint64_t honest = worker(), rogue = worker();
  const v1::GetTaskResponse held = c->get_task(honest, 4);
  ASSERT_EQ(held.tasks_size(), 4);
  for (const v1::Task& task : held.tasks()) {
    v1::TaskResult forged = render_task(task, rogue);  // a registered worker, not the holder
    EXPECT_FALSE(c->submit_result(forged).accepted());
    forged.set_worker_id(987654);  // never registered
    EXPECT_FALSE(c->submit_result(forged).accepted());
  }
  EXPECT_EQ(c->counters().results_rejected, 8u);
  EXPECT_EQ(c->counters().results_merged, 0u);
  // The holder's results still merge, also after its lease expired.
  t += 10;
  c->expire_leases();
  for (const v1::Task& task : held.tasks()) EXPECT_TRUE(c->submit_result(render_task(task, honest)).accepted());
  drain(honest);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// Issue 10, row 5: a Register loop made 20,000 workers that were never removed. Workers
// are capped, silent ones are forgotten, and leaving frees a place.
TEST_F(CoordinatorTest, RegisteredWorkersAreBounded) {
  CoordinatorOptions o = options();
  o.max_workers = 3;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const uint64_t first = worker();
  worker();
  worker();
  try {
    worker();
    ADD_FAILURE();
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_NE(std::string(e.what()).find("3 workers"), std::string::npos) << e.what();
  }
  c->unregister(first);
  EXPECT_NO_THROW(worker());
  t += o.worker_timeout_seconds + 1;  // all silent: forgotten when the next one registers
  EXPECT_NO_THROW(worker());
  EXPECT_EQ(c->workers().size(), 1u);
}

// A worker's name and host are kept to 256 bytes, cut on a character boundary: a cut
// through "\xC3\xA9" left a byte that is not UTF-8, which made every /api/status answer
// (a strict JSON dump) fail while that worker stayed registered.
TEST_F(CoordinatorTest, AWorkersNameAndHostAreCutOnCharacterBoundaries) {
  v1::RegisterRequest r;
  r.set_version(kProtocolVersion);
  r.set_name(std::string(255, 'a') + "\xC3\xA9");
  r.set_host(std::string(254, 'h') + "\xE2\x82\xAC");
  const uint64_t id = c->register_worker(r).worker_id();
  ASSERT_EQ(c->workers().size(), 1u);
  EXPECT_EQ(c->workers()[0].id, id);
  EXPECT_EQ(c->workers()[0].name, std::string(255, 'a'));
  EXPECT_EQ(c->workers()[0].host, std::string(254, 'h'));
}

// Found by audit: workers of one name and host were told apart by "#2", "#3" counted per
// name alone, so workers named "a", "a" and "a#2" gave two series labelled "a#2", which the
// exposition format forbids (Prometheus drops one; promtool fails the page).
TEST_F(CoordinatorTest, EachWorkersMetricsSeriesIsLabelledUniquely) {
  for (const char* name : {"a", "a", "a#2", "a#2"}) {
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name(name);
    r.set_host("h");
    c->register_worker(r);
  }
  const std::string text = prometheus_text(*c);
  std::set<std::string> series;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("tessera_worker_tasks_total{", 0) == 0) {
      EXPECT_TRUE(series.insert(line.substr(0, line.find('}'))).second) << line;
    }
  }
  EXPECT_EQ(series.size(), 4u) << text;
  EXPECT_TRUE(series.count("tessera_worker_tasks_total{worker=\"a\",host=\"h\"")) << text;
}

// A heartbeat lists the tasks a worker holds: at most twice --max-leases-per-worker, so
// that one cannot hold the coordinator's lock for millions of lookups.
TEST_F(CoordinatorTest, AHeartbeatListsAtMostTwiceTheLeasesAWorkerMayHold) {
  CoordinatorOptions o = options();
  o.max_leases_per_worker = 4;
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const uint64_t w = worker();
  std::vector<uint64_t> ids(8);
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = 1000 + i;
  EXPECT_EQ(c->heartbeat(w, ids, 0).size(), 8u);  // none of them its lease: all refused
  ids.push_back(2000);
  try {
    c->heartbeat(w, ids, 0);
    ADD_FAILURE();
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("9 tasks listed; at most 8 (twice --max-leases-per-worker)"),
              std::string::npos)
        << e.what();
  }
}

// Issue 10, row 3: with the data folder full or read-only, the write error went back to
// the worker as a failed result (so it resent), nothing was logged, and a DONE job could
// not be fetched. Now results are accepted, the job says why its image is missing without
// naming server paths, a fetch gets a clear error, and the write is retried.

}  // namespace
}  // namespace tessera
