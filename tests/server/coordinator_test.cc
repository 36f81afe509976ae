// The coordinator in-process with a fake clock: a job's life through its public calls,
// ordered merging, leases, duplicates, hostile results, refusals, images.
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

TEST_F(CoordinatorTest, MergedImageEqualsTheLocalRenderBitForBit) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  drain(worker());
  const v1::JobStatus st = c->status(id, true);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.samples_done(), 48u * 36u * 10u);
  EXPECT_EQ(st.tiles_done(), st.tiles_total());
  EXPECT_EQ(st.frame_passes_done(), 3u);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(CoordinatorTest, OutOfOrderWorkersAndAdaptiveSamplingStillMatch) {
  RenderSettings s = job_settings();
  s.spp = 40;
  s.adaptive = true;
  s.adaptive_batch = 8;
  s.adaptive_tolerance = 0.3f;
  const std::string id = c->submit(request(s));
  const uint64_t a = worker(), b = worker();
  // Hold several tasks at once and answer them in reverse order.
  for (int round = 0; round < 1000; ++round) {
    std::vector<std::pair<v1::Task, uint64_t>> held;
    for (uint64_t w : {a, b, a, b}) {
      v1::GetTaskResponse r = c->get_task(w);
      if (r.tasks_size() > 0) held.emplace_back(r.tasks(0), w);
    }
    if (held.empty()) break;
    for (auto it = held.rbegin(); it != held.rend(); ++it)
      ASSERT_TRUE(c->submit_result(render_task(it->first, it->second)).accepted());
  }
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(CoordinatorTest, DuplicateResultIsDropped) {
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const v1::Task task = c->get_task(w).tasks(0);
  const v1::TaskResult res = render_task(task, w);
  EXPECT_TRUE(c->submit_result(res).accepted());
  const v1::ResultAck again = c->submit_result(res);
  EXPECT_FALSE(again.accepted());
  EXPECT_TRUE(again.duplicate());
  EXPECT_EQ(c->counters().results_duplicate, 1u);
  EXPECT_EQ(c->status(id, false).samples_done(), uint64_t(task.tile().w() * task.tile().h() * 4));
}

TEST_F(CoordinatorTest, ExpiredLeaseGoesToAnotherWorkerAndTheLateResultIsNotMergedTwice) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const uint64_t slow = worker(), fast = worker();
  const v1::Task first = c->get_task(slow).tasks(0);
  t += 2;
  EXPECT_TRUE(c->heartbeat(slow, first.task_id()));  // renewed to t + 5
  t += 4;
  EXPECT_EQ(c->expire_leases(), 0u);
  t += 2;  // silent for 6 s > 5 s lease
  EXPECT_EQ(c->expire_leases(), 1u);
  EXPECT_FALSE(c->heartbeat(slow, first.task_id()));  // the slow worker is told to stop
  // The same tile pass goes to the other worker (fewest passes first).
  const v1::Task retry = c->get_task(fast).tasks(0);
  EXPECT_EQ(retry.tile().x(), first.tile().x());
  EXPECT_EQ(retry.tile().y(), first.tile().y());
  EXPECT_EQ(retry.pass(), first.pass());
  EXPECT_NE(retry.task_id(), first.task_id());
  // The slow worker's result arrives after all: identical bits, merged once.
  EXPECT_TRUE(c->submit_result(render_task(first, slow)).accepted());
  const v1::ResultAck late = c->submit_result(render_task(retry, fast));
  EXPECT_TRUE(late.duplicate());
  drain(fast);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(CoordinatorTest, HostileResultsAreRejectedAndCounted) {
  c->submit(request(job_settings()));
  const uint64_t w = worker();
  const v1::Task task = c->get_task(w).tasks(0);
  v1::TaskResult bad = render_task(task, w);
  bad.set_task_id(999999);  // never issued
  EXPECT_FALSE(c->submit_result(bad).accepted());
  bad = render_task(task, w);
  bad.set_sums_zstd("not zstd at all");
  EXPECT_FALSE(c->submit_result(bad).accepted());
  bad = render_task(task, w);
  bad.set_raw_size(bad.raw_size() + 36);  // wrong size
  EXPECT_FALSE(c->submit_result(bad).accepted());
  // More samples per pixel than the pass has.
  std::vector<PixelSums> sums(size_t(task.tile().w() * task.tile().h()));
  for (PixelSums& p : sums) p.n = 1000;
  bad.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
  bad.set_sums_zstd(encode_sums(sums));
  EXPECT_FALSE(c->submit_result(bad).accepted());
  EXPECT_EQ(c->counters().results_rejected, 4u);
  EXPECT_TRUE(c->submit_result(render_task(task, w)).accepted());  // the real one still merges
}

TEST_F(CoordinatorTest, ABatchOfResultsIsAnsweredResultByResultInOrder) {
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const v1::GetTaskResponse tasks = c->get_task(w, 3);
  ASSERT_EQ(tasks.tasks_size(), 3);
  const v1::TaskResult first = render_task(tasks.tasks(0), w), third = render_task(tasks.tasks(2), w);
  v1::TaskResult broken = render_task(tasks.tasks(1), w);
  broken.set_sums_zstd("not zstd at all");
  v1::TaskResult stranger = third;
  stranger.set_worker_id(w + 1000);  // not the lease's holder
  // Good, malformed, good, the first again in the same batch, someone else's answer.
  const std::vector<v1::ResultAck> acks = c->submit_results({&first, &broken, &third, &first, &stranger});
  ASSERT_EQ(acks.size(), 5u);
  EXPECT_TRUE(acks[0].accepted());
  EXPECT_FALSE(acks[1].accepted());
  EXPECT_FALSE(acks[1].duplicate());
  EXPECT_TRUE(acks[2].accepted());
  EXPECT_FALSE(acks[3].accepted());
  EXPECT_TRUE(acks[3].duplicate());
  EXPECT_FALSE(acks[4].accepted());
  EXPECT_EQ(c->counters().results_merged, 2u);
  EXPECT_EQ(c->counters().results_duplicate, 1u);
  EXPECT_EQ(c->counters().results_rejected, 2u);
  // The malformed one's tile is still wanted: its real result merges, and the job ends
  // with the image a local render makes.
  EXPECT_TRUE(c->submit_result(render_task(tasks.tasks(1), w)).accepted());
  t += JobLifecycle::kFirstRestSeconds;  // (the malformed one failed a task here: the worker rested from the job)
  drain(w);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(job_settings()), read_exr(image_path(id, "image.exr"))));
}

TEST_F(CoordinatorTest, MalformedSceneIsRefusedAtSubmitAndOthersStillRun) {
  v1::SubmitJobRequest bad = request(job_settings());
  bad.mutable_files(0)->set_content("<COLLADA><scene><instance_visual_scene url=\"#gone\"/></scene></COLLADA>");
  try {
    c->submit(bad);
    ADD_FAILURE();
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kInvalidArgument);
    EXPECT_NE(std::string(e.what()).find("cornell-spheres.dae: "), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("dangling reference '#gone'"), std::string::npos) << e.what();
  }
  v1::SubmitJobRequest far = request(job_settings());  // loads, but cannot be traced
  std::string text = far.files(0).content();
  text.replace(text.find("-1 -0.75 -1 -1 -0.75 1"), 2, "99999999999999999999");
  far.mutable_files(0)->set_content(text);
  try {
    c->submit(far);
    ADD_FAILURE();
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("cornell-spheres.dae: mesh '"), std::string::npos) << e.what();
  }
  v1::SubmitJobRequest traversal = request(job_settings());
  traversal.mutable_files(0)->set_path("../../etc/x.dae");
  traversal.set_main_file("../../etc/x.dae");
  EXPECT_THROW(c->submit(traversal), RequestError);
  v1::SubmitJobRequest zero = request(job_settings());
  zero.mutable_settings()->set_spp(0);
  EXPECT_THROW(c->submit(zero), RequestError);
  v1::SubmitJobRequest old = request(job_settings());
  old.set_version(99);
  EXPECT_THROW(c->submit(old), RequestError);
  EXPECT_EQ(c->counters().jobs_refused, 5u);
  const std::string id = c->submit(request(job_settings()));
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
}

TEST_F(CoordinatorTest, CancelStopsDispatchAndKeepsWhatWasRendered) {
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const v1::Task a = c->get_task(w).tasks(0);
  ASSERT_TRUE(c->submit_result(render_task(a, w)).accepted());
  const v1::Task b = c->get_task(w).tasks(0);
  EXPECT_EQ(c->cancel(id).state(), v1::JobStatus::CANCELLED);
  EXPECT_FALSE(c->heartbeat(w, b.task_id()));
  EXPECT_FALSE(c->get_task(w).tasks_size() > 0);
  const ExrImage img = read_exr(image_path(id, "image.exr"));
  float spp = 0;
  for (float n : img.channels.at("spp")) spp += n;
  EXPECT_EQ(spp, float(a.tile().w() * a.tile().h() * 4));  // the merged tile is in the image
}

// Regression: the merge that ends a job writes its final image after releasing the lock,
// so a client that saw DONE and fetched at once got the previous progressive image (seen
// in CI as a farm image with fewer samples than the local one). The seam holds the merging
// thread inside that window.
// An image is final only once its job has ended (and then it holds the whole film): a
// client told the job ended writes no other (FarmClient.SubmitWaitWritesNoImageThatIsNotFinal).
TEST_F(CoordinatorTest, OnlyAnEndedJobsImageIsFinal) {
  const std::string id = c->submit(request(job_settings()));
  const uint64_t w = worker();
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  EXPECT_FALSE(c->image(id, true, false).final());
  drain(w);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(c->image(id, true, false).final());
}

TEST_F(CoordinatorTest, ImageFetchedAsSoonAsTheJobEndsHoldsEverySample) {
  std::atomic<std::thread::id> slow;
  CoordinatorOptions o = options();
  o.before_image_write = [&] {
    if (std::this_thread::get_id() == slow.load()) std::this_thread::sleep_for(std::chrono::milliseconds(300));
  };
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  RenderSettings s = job_settings();
  s.spp = 4;
  s.pass_spp = 2;  // two passes: the first one ends in a progressive image
  const uint64_t w = worker();
  auto lease_all = [&] {
    std::vector<v1::TaskResult> results;
    for (v1::GetTaskResponse r = c->get_task(w); r.tasks_size() > 0; r = c->get_task(w))
      results.push_back(render_task(r.tasks(0), w));
    return results;
  };
  const std::string id = c->submit(request(s));
  for (const v1::TaskResult& r : lease_all()) ASSERT_TRUE(c->submit_result(r).accepted());
  ASSERT_EQ(c->status(id, false).frame_passes_done(), 1u);
  ASSERT_GE(c->counters().images_written, 1u);
  const std::vector<v1::TaskResult> second = lease_all();
  for (size_t i = 0; i + 1 < second.size(); ++i) ASSERT_TRUE(c->submit_result(second[i]).accepted());
  std::thread last([&] {
    slow = std::this_thread::get_id();
    c->submit_result(second.back());
  });
  while (c->status(id, false).state() != v1::JobStatus::DONE) std::this_thread::yield();
  const v1::Image img = c->image(id);
  last.join();
  const std::string path = dir + "/fetched.exr";
  std::ofstream(path, std::ios::binary) << img.exr();
  const ExrImage fetched = read_exr(path);
  EXPECT_TRUE(same_film_as_exr(local(s), fetched));
  // The late final write does not replace the newer image with an older one.
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(CoordinatorTest, HigherPriorityJobsGoFirst) {
  const std::string low = c->submit(request(job_settings()));
  v1::SubmitJobRequest r = request(job_settings());
  r.set_priority(5);
  const std::string high = c->submit(r);
  EXPECT_EQ(c->get_task(worker()).tasks(0).job_id(), high);
  (void)low;
}

TEST_F(CoordinatorTest, NoiseTargetStopsConvergedTilesEarlyAndReproducibly) {
  RenderSettings s = job_settings();
  s.spp = 64;
  s.pass_spp = 8;
  s.noise_target = 0.5;
  const v1::SubmitJobRequest r = request(s);
  const std::string a = c->submit(r), b = c->submit(r);
  drain(worker());
  const v1::JobStatus sa = c->status(a, true), sb = c->status(b, true);
  EXPECT_EQ(sa.state(), v1::JobStatus::DONE);
  EXPECT_LT(sa.samples_done(), sa.samples_total());  // some tiles stopped early
  EXPECT_EQ(sa.samples_done(), sb.samples_done());   // and the same ones each time
  for (const auto& tile : sa.tiles()) EXPECT_TRUE(tile.passes_done() == 8 || tile.relative_error() <= 0.5);
  // The image as it was before the frame plan took over the schedule (commit fba7d1d),
  // re-derived when Accel capped Embree at AVX and when it computed triangle hits itself
  // (golden_test.cc says how).
  EXPECT_EQ(exr_hash(read_exr(image_path(a, "image.exr"))), 13990042746610062949ull);
  // `tessera render --noise-target` is the same frame plan: the same tiles stop, bit for bit.
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(a, "image.exr"))));
}

// The image sink is a seam: with films kept in memory the coordinator needs no disk for
// images, and the merged film equals the local render in every bit of every sum.
TEST_F(CoordinatorTest, ImagesGoToTheSinkAndHoldTheLocalFilmsExactBits) {
  auto sink = std::make_unique<MemoryImageSink>();
  MemoryImageSink* images = sink.get();
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t), std::move(sink));
  RenderSettings s = job_settings();
  s.adaptive = true;
  s.adaptive_batch = 4;
  s.adaptive_tolerance = 0.3f;
  const std::string id = c->submit(request(s));
  drain(worker());
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  const Film merged = images->film(id), expected = local(s);
  ASSERT_EQ(merged.pixels().size(), expected.pixels().size());
  for (size_t i = 0; i < merged.pixels().size(); ++i) {
    const PixelSums &a = merged.pixels()[i], &b = expected.pixels()[i];
    ASSERT_TRUE(std::memcmp(&a.r, &b.r, 8) == 0 && std::memcmp(&a.g, &b.g, 8) == 0 && std::memcmp(&a.b, &b.b, 8) == 0 &&
                std::memcmp(&a.lum2, &b.lum2, 8) == 0 && a.n == b.n)
        << "pixel " << i;
  }
  EXPECT_EQ(images->metadata(id).at("job"), id);
  EXPECT_GE(images->writes(id), 1);
}

// GetTask's long poll returns at the first change, not at its timeout (a regression that
// left workers idle a second at a time was caught by the network namespace test).
TEST_F(CoordinatorTest, WaitingForWorkEndsAtTheFirstChange) {
  std::thread submitter([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    c->submit(request(job_settings()));
  });
  const auto start = std::chrono::steady_clock::now();
  c->wait_for_work(30);
  submitter.join();
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 20);
}

TEST_F(CoordinatorTest, UnknownWorkerMustRegisterAgain) { EXPECT_THROW(c->get_task(12345), RequestError); }

// Workers report render-thread time with results; utilization is busy over available time
// in a recent window. Silent workers are forgotten, so gauges count live workers only.
TEST_F(CoordinatorTest, UtilizationFromReportsAndSilentWorkersAreForgotten) {
  c->submit(request(job_settings()));
  const uint64_t w = worker(), idle = worker();
  v1::TaskResult r = render_task(c->get_task(w).tasks(0), w);
  r.set_busy_thread_seconds(1.0);
  r.set_thread_seconds(2.0);
  ASSERT_TRUE(c->submit_result(r).accepted());
  for (const WorkerInfo& info : c->workers()) {
    if (info.id == w) {
      EXPECT_NEAR(info.utilization, 0.5, 1e-12);  // since it registered
    }
  }
  t += 6;  // past the 5 s window: the next report starts a new one from the last
  r = render_task(c->get_task(w).tasks(0), w);
  r.set_busy_thread_seconds(2.9);  // of the 2 thread-seconds since the last report, 95% busy
  r.set_thread_seconds(4.0);
  ASSERT_TRUE(c->submit_result(r).accepted());
  double util = -1;
  for (const WorkerInfo& info : c->workers())
    if (info.id == w) util = info.utilization;
  EXPECT_NEAR(util, 0.95, 1e-12);
  // The farm's: the idle worker's thread counts as a window of unused time.
  EXPECT_NEAR(c->utilization(), 1.9 / (2 + WorkerRegistry::kWindowSeconds), 1e-12);
  // Reports that go backwards are not believed.
  r = render_task(c->get_task(w).tasks(0), w);
  r.set_busy_thread_seconds(0.5);
  r.set_thread_seconds(1.0);
  ASSERT_TRUE(c->submit_result(r).accepted());
  EXPECT_NEAR(c->utilization(), 1.9 / (2 + WorkerRegistry::kWindowSeconds), 1e-12);
  EXPECT_EQ(c->workers().size(), 2u);
  t += options().worker_timeout_seconds / 2;
  c->get_task(w);  // w is heard from; idle is not
  t += options().worker_timeout_seconds / 2 + 1;
  c->expire_leases();
  ASSERT_EQ(c->workers().size(), 1u);
  EXPECT_EQ(c->workers()[0].id, w);
  EXPECT_THROW(c->get_task(idle), RequestError);  // told to register again
  // Issue 24: a farm with nothing to do is 0% busy, not its last figure.
  EXPECT_EQ(c->workers()[0].utilization, 0);
  EXPECT_EQ(c->utilization(), 0);
}

// A worker asks for as many tasks as keep it busy: a count and a sample budget. Each task
// is its own lease, and the image is still the local one bit for bit.

TEST_F(CoordinatorTest, ImageWriteFailuresAreReportedAndRetriedNeverBlamedOnWorkers) {
  class FlakySink : public MemoryImageSink {
   public:
    explicit FlakySink(std::string dir) : dir_(std::move(dir)) {}
    std::atomic<bool> fail{true};
    void write(const std::string& job, const Film& film, const ImageMetadata& meta) override {
      if (fail) throw std::runtime_error(dir_ + "/jobs/" + job + "/image.exr.tmp: No space left on device");
      MemoryImageSink::write(job, film, meta);
    }

   private:
    std::string dir_;
  };
  auto owned = std::make_unique<FlakySink>(dir);
  FlakySink* sink = owned.get();
  c.reset();  // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t), std::move(owned));
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  drain(worker());  // every result accepted (drain asserts it)
  const v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_NE(st.error().find("image not written: <data>/jobs/"), std::string::npos) << st.error();
  EXPECT_NE(st.error().find("No space left on device"), std::string::npos) << st.error();
  EXPECT_EQ(st.error().find(dir), std::string::npos) << "a server path in " << st.error();
  EXPECT_GE(c->counters().image_errors, 1u);
  EXPECT_EQ(c->counters().results_rejected, 0u);
  try {
    c->image(id);
    ADD_FAILURE();
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kFailedPrecondition);
    EXPECT_NE(std::string(e.what()).find("could not be written"), std::string::npos) << e.what();
  }
  sink->fail = false;  // space again: the next fetch writes the final image
  EXPECT_NO_THROW(c->image(id));
  EXPECT_EQ(c->status(id, false).error(), "");
  const Film written = sink->film(id), expected = local(s);
  ASSERT_EQ(written.pixels().size(), expected.pixels().size());
  for (size_t i = 0; i < written.pixels().size(); ++i) ASSERT_EQ(written.pixels()[i].n, expected.pixels()[i].n);
}

// Issue 10: a task no worker can render no longer goes round forever. One worker's
// failure puts the tile back for another; failures on two workers fail the job with the
// error, keep what was rendered, and the queue moves on to the next job.
TEST_F(CoordinatorTest, TasksFailingOnTwoWorkersFailTheJobAndTheQueueMovesOn) {
  v1::SubmitJobRequest first = request(job_settings());
  first.set_priority(1);
  const std::string doomed = c->submit(first), next = c->submit(request(job_settings()));
  const uint64_t a = worker(), b = worker();
  const v1::Task ta = c->get_task(a).tasks(0);
  ASSERT_EQ(ta.job_id(), doomed);
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(a).tasks(0), a)).accepted());  // some work is done
  c->release(a, ta.task_id(), "cannot load scene: out of memory");
  EXPECT_EQ(c->status(doomed, false).state(), v1::JobStatus::RUNNING);  // maybe just a's trouble
  const v1::Task tb = c->get_task(b).tasks(0);
  EXPECT_EQ(tb.tile().x(), ta.tile().x());  // the same tile, straight away
  EXPECT_EQ(tb.tile().y(), ta.tile().y());
  c->release(b, tb.task_id(), "cannot load scene: out of memory");
  const v1::JobStatus st = c->status(doomed, false);
  EXPECT_EQ(st.state(), v1::JobStatus::FAILED);
  EXPECT_EQ(st.error(), "tasks failed on 2 workers: cannot load scene: out of memory");
  EXPECT_EQ(c->counters().tasks_failed, 2u);
  EXPECT_GT(c->image(doomed).exr().size(), 0u);  // what was rendered is kept
  drain(b);
  EXPECT_EQ(c->status(next, false).state(), v1::JobStatus::DONE);
}

// Issue 10, row 9: scenes were kept in memory and on disk forever. A scene is served to
// workers (in memory) as long as a live job uses it, and stays on disk while any job names
// it (a requeue goes on with it): it goes with the last of them to be deleted.
TEST_F(CoordinatorTest, ScenesAreServedWhileALiveJobUsesThemAndGoWithTheirLastJob) {
  const std::string a = c->submit(request(job_settings())), b = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const std::string hash = c->get_task(w).tasks(0).scene_hash();
  const fs::path on_disk = fs::path(dir) / "scenes" / hash;
  EXPECT_TRUE(fs::exists(on_disk));
  c->cancel(a);
  EXPECT_NO_THROW(c->scene(hash));  // b still needs it
  EXPECT_TRUE(fs::exists(on_disk));
  drain(w);
  ASSERT_EQ(c->status(b, false).state(), v1::JobStatus::DONE);
  EXPECT_THROW(c->scene(hash), RequestError);
  EXPECT_TRUE(fs::exists(on_disk));
  EXPECT_GT(c->image(b).exr().size(), 0u);
  const std::string again = c->submit(request(job_settings()));  // checked afresh
  EXPECT_NO_THROW(c->scene(hash));
  drain(w);
  EXPECT_EQ(c->status(again, false).state(), v1::JobStatus::DONE);
  for (const std::string& id : {a, b}) {
    c->remove(id);
    EXPECT_TRUE(fs::exists(on_disk));  // `again` names it
  }
  EXPECT_GT(c->remove(again), 0u);
  EXPECT_FALSE(fs::exists(on_disk));
  EXPECT_TRUE(fs::is_empty(fs::path(dir) / "jobs"));
}

// Issue 22: a scene sent in pieces is a scene like one sent whole: the same hash, the same
// image; workers get it in pieces from the coordinator's disk, and it goes with its job.
TEST_F(CoordinatorTest, AnUploadedSceneRendersAsOneSentWhole) {
  const v1::SceneUpload up = upload();
  const v1::SubmitJobRequest whole = request(job_settings());
  EXPECT_EQ(up.scene_hash(), bundle_hash(whole.main_file(), whole.files()));
  const std::string id = c->submit(request(job_settings(), up));
  EXPECT_EQ(c->status(id, false).name(), "cornell-spheres.dae");
  EXPECT_EQ(c->scene(up.scene_hash()).main_file(), "cornell-spheres.dae");
  v1::FetchSceneRequest fetch;
  fetch.set_scene_hash(up.scene_hash());
  std::string bytes;
  c->scene_chunks(fetch, [&](const v1::SceneChunk& piece) {
    bytes += piece.data();
    return true;
  });
  EXPECT_EQ(bytes, whole.files(0).content());
  const uint64_t w = worker();
  drain(w);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(job_settings()), read_exr(image_path(id, "image.exr"))));
  EXPECT_THROW(c->scene(up.scene_hash()), RequestError);  // no live job uses it
  c->remove(id);
  EXPECT_FALSE(fs::exists(fs::path(dir) / "scenes" / up.scene_hash()));
  try {
    c->submit(request(job_settings(), up));  // an upload names one submit
    ADD_FAILURE() << "an upload used twice";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kNotFound);
  }
}

TEST_F(CoordinatorTest, QueueDepthCountsWhatIsLeft) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  Coordinator::Queue q = c->queue();
  EXPECT_EQ(q.tasks_ready, 9u);  // 48x36 in 16-pixel tiles, first passes
  EXPECT_EQ(q.tasks_leased, 0u);
  EXPECT_EQ(q.samples_remaining, 48u * 36u * 10u);
  EXPECT_EQ(q.samples_per_thread_second, Coordinator::kAssumedThreadSpeed);
  EXPECT_DOUBLE_EQ(q.core_seconds_remaining, 48.0 * 36 * 10 / Coordinator::kAssumedThreadSpeed);
  const uint64_t w = worker();
  const v1::GetTaskResponse r = c->get_task(w, 2);
  EXPECT_EQ(c->queue().tasks_leased, 2u);
  v1::TaskResult res = render_task(r.tasks(0), w);
  res.set_render_seconds(0.5);  // a measured speed: samples / 0.5 s on one thread
  ASSERT_TRUE(c->submit_result(res).accepted());
  q = c->queue();
  EXPECT_EQ(q.samples_per_thread_second, double(res.samples()) / 0.5);
  EXPECT_DOUBLE_EQ(q.core_seconds_remaining, double(q.samples_remaining) / q.samples_per_thread_second);
  ASSERT_TRUE(c->submit_result(render_task(r.tasks(1), w)).accepted());
  drain(w);
  q = c->queue();
  EXPECT_EQ(q.tasks_ready + q.tasks_leased + q.samples_remaining, 0u);
  EXPECT_EQ(c->unready_reason(), "");
  (void)id;
}

}  // namespace
}  // namespace tessera
