// The coordinator's logic driven in-process, with a fake clock: ordered merging, leases,
// duplicates, hostile results, refusals.
#include "server/coordinator.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "tests/core/test_paths.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

class FakeClock : public Clock {
 public:
  explicit FakeClock(double* t) : t_(t) {}
  double now() const override { return *t_; }

 private:
  double* t_;
};

RenderSettings job_settings() {
  RenderSettings s;
  s.camera.width = 48;
  s.camera.height = 36;
  s.spp = 10;
  s.pass_spp = 4;  // passes of 4, 4, 2
  s.max_depth = 6;
  s.seed = 3;
  s.tile_size = 16;
  return s;
}

class CoordinatorTest : public ::testing::Test {
 protected:
  double t = 1000;
  std::string dir = (fs::temp_directory_path() / ("tessera_coord_" + std::to_string(::getpid()))).string();
  std::unique_ptr<Coordinator> c;
  std::string scene_path = testing::source_path("scenes/cornell-spheres.dae");
  Scene scene = load_scene(scene_path);

  CoordinatorOptions options() const {
    CoordinatorOptions o;
    o.data_dir = dir;
    o.lease_seconds = 5;
    o.image_interval_seconds = 0;
    o.verify_fraction = 0;  // checks are random: VerifyTest turns them on
    return o;
  }
  std::string image_path(const std::string& id, const char* file) const { return dir + "/jobs/" + id + "/" + file; }
  void SetUp() override { c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t)); }
  void TearDown() override { fs::remove_all(dir); }

  v1::SubmitJobRequest request(const RenderSettings& s) {
    v1::SubmitJobRequest r;
    r.set_version(kProtocolVersion);
    std::string main;
    pack_scene(scene_path, &main, r.mutable_files());
    r.set_main_file(main);
    *r.mutable_settings() = to_proto(s);
    return r;
  }
  uint64_t worker() {
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name("test");
    return c->register_worker(r).worker_id();
  }
  v1::TaskResult render_task(const v1::Task& task, uint64_t worker_id) {
    const TileRenderer r(scene, from_proto(task.settings()));
    const Rect tile = from_proto(task.tile());
    const auto* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
    TileStats stats;
    const auto sums = r.render(tile, task.sample_begin(), task.sample_end(), mask, &stats);
    v1::TaskResult res;
    res.set_worker_id(worker_id);
    res.set_task_id(task.task_id());
    res.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
    res.set_sums_zstd(encode_sums(sums));
    res.set_samples(stats.samples);
    res.set_render_seconds(0.01);
    return res;
  }
  // Runs the job to the end with one worker, in task order.
  void drain(uint64_t w) {
    for (int guard = 0; guard < 100000; ++guard) {
      const v1::GetTaskResponse r = c->get_task(w);
      if (r.tasks_size() == 0) return;
      ASSERT_TRUE(c->submit_result(render_task(r.tasks(0), w)).accepted());
    }
  }
  Film local(const RenderSettings& s) { return render_image(TileRenderer(scene, s), 2).film; }
};

bool same_film_as_exr(const Film& film, const ExrImage& img) {
  if (img.width != film.width() || img.height != film.height()) return false;
  for (size_t i = 0; i < film.pixels().size(); ++i) {
    const Rgb m = film.pixels()[i].mean();
    if (std::memcmp(&m.r, &img.channels.at("R")[i], 4) || std::memcmp(&m.g, &img.channels.at("G")[i], 4) ||
        std::memcmp(&m.b, &img.channels.at("B")[i], 4) || img.channels.at("spp")[i] != float(film.pixels()[i].n))
      return false;
  }
  return true;
}

// FNV-1a over the EXR's R, G, B and spp channels.
uint64_t exr_hash(const ExrImage& img) {
  uint64_t h = 1469598103934665603ull;
  for (const char* c : {"R", "G", "B", "spp"})
    for (float v : img.channels.at(c)) {
      const auto* b = reinterpret_cast<const unsigned char*>(&v);
      for (size_t i = 0; i < sizeof v; ++i) h = (h ^ b[i]) * 1099511628211ull;
    }
  return h;
}

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
TEST_F(CoordinatorTest, ImageFetchedAsSoonAsTheJobEndsHoldsEverySample) {
  std::atomic<std::thread::id> slow;
  CoordinatorOptions o = options();
  o.before_image_write = [&] {
    if (std::this_thread::get_id() == slow.load()) std::this_thread::sleep_for(std::chrono::milliseconds(300));
  };
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
  // The image as it was before the frame plan took over the schedule (commit fba7d1d).
  EXPECT_EQ(exr_hash(read_exr(image_path(a, "image.exr"))), 3625336713443161310ull);
  // `tessera render --noise-target` is the same frame plan: the same tiles stop, bit for bit.
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(a, "image.exr"))));
}

// The image sink is a seam: with films kept in memory the coordinator needs no disk for
// images, and the merged film equals the local render in every bit of every sum.
TEST_F(CoordinatorTest, ImagesGoToTheSinkAndHoldTheLocalFilmsExactBits) {
  auto sink = std::make_unique<MemoryImageSink>();
  MemoryImageSink* images = sink.get();
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
  EXPECT_NEAR(c->utilization(), 0.95, 1e-12);
  // Reports that go backwards are not believed.
  r = render_task(c->get_task(w).tasks(0), w);
  r.set_busy_thread_seconds(0.5);
  r.set_thread_seconds(1.0);
  ASSERT_TRUE(c->submit_result(r).accepted());
  EXPECT_NEAR(c->utilization(), 0.95, 1e-12);
  EXPECT_EQ(c->workers().size(), 2u);
  t += options().worker_timeout_seconds / 2;
  c->get_task(w);  // w is heard from; idle is not
  t += options().worker_timeout_seconds / 2 + 1;
  c->expire_leases();
  ASSERT_EQ(c->workers().size(), 1u);
  EXPECT_EQ(c->workers()[0].id, w);
  EXPECT_THROW(c->get_task(idle), RequestError);  // told to register again
}

// A worker asks for as many tasks as keep it busy: a count and a sample budget. Each task
// is its own lease, and the image is still the local one bit for bit.
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
  o.max_live_pixels = 4 * 48 * 36;  // four of job_settings()'s frames
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

TEST_F(CoordinatorTest, SceneBytesAndQueuedSamplesPerClientAreBounded) {
  const v1::SubmitJobRequest one = request(job_settings());
  uint64_t bytes = 0;
  for (const v1::SceneFile& f : one.files()) bytes += f.path().size() + f.content().size();
  CoordinatorOptions o = options();
  o.max_scene_bytes_per_client = 2 * bytes;  // two jobs' scenes
  o.max_queued_samples_per_client = 3 * 48 * 36 * 10;
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

// Issue 10, row 3: with the data folder full or read-only, the write error went back to
// the worker as a failed result (so it resent), nothing was logged, and a DONE job could
// not be fetched. Now results are accepted, the job says why its image is missing without
// naming server paths, a fetch gets a clear error, and the write is retried.
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

// Issue 10, row 9: scenes were kept in memory and on disk forever. A scene now lives as
// long as a live job uses it; a job's image outlives it.
TEST_F(CoordinatorTest, ScenesGoWhenTheirLastJobEnds) {
  const std::string a = c->submit(request(job_settings())), b = c->submit(request(job_settings()));
  const uint64_t w = worker();
  const std::string hash = c->get_task(w).tasks(0).scene_hash();
  const fs::path on_disk = fs::path(dir) / "scenes" / (hash + ".bundle");
  EXPECT_TRUE(fs::exists(on_disk));
  c->cancel(a);
  EXPECT_NO_THROW(c->scene(hash));  // b still needs it
  EXPECT_TRUE(fs::exists(on_disk));
  drain(w);
  ASSERT_EQ(c->status(b, false).state(), v1::JobStatus::DONE);
  EXPECT_THROW(c->scene(hash), RequestError);
  EXPECT_FALSE(fs::exists(on_disk));
  EXPECT_GT(c->image(b).exr().size(), 0u);                       // the image stays
  const std::string again = c->submit(request(job_settings()));  // checked afresh
  EXPECT_NO_THROW(c->scene(hash));
  drain(w);
  EXPECT_EQ(c->status(again, false).state(), v1::JobStatus::DONE);
}

// ---- crash safety: a coordinator made again on the same data folder ----------------------

// Takes the coordinator down without a word (as kill -9 would: nothing is written on the
// way out) and starts a new one on the same data folder.
void restart(std::unique_ptr<Coordinator>& c, const CoordinatorOptions& o, double* t) {
  c.reset();
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(t));
}

TEST_F(CoordinatorTest, ARestartedCoordinatorGoesOnWithEveryJobInItsState) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string done = c->submit(request(s));
  drain(w);
  const std::string cancelled = c->submit(request(s));
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  c->cancel(cancelled);
  const std::string live = c->submit(request(s));
  const std::string waiting = c->submit(request(s), "someone");
  for (int k = 0; k < 5; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;  // past checkpoint_seconds: the next merge writes a checkpoint
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t at_checkpoint = c->status(live, false).samples_done();
  for (int k = 0; k < 2; ++k)  // merged after the checkpoint: lost with the coordinator
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const v1::Task in_flight = c->get_task(w).tasks(0);
  const std::vector<v1::JobStatus> before = c->list();

  restart(c, options(), &t);
  const std::vector<v1::JobStatus> after = c->list();
  ASSERT_EQ(after.size(), before.size());
  for (size_t i = 0; i < after.size(); ++i) {
    EXPECT_EQ(after[i].id(), before[i].id());
    EXPECT_EQ(after[i].name(), before[i].name());
    EXPECT_EQ(after[i].owner(), before[i].owner());
    EXPECT_EQ(after[i].state(), before[i].state()) << i;
  }
  EXPECT_EQ(c->status(done, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(done, false).samples_done(), c->status(done, false).samples_total());
  EXPECT_EQ(c->status(cancelled, false).state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(c->status(live, false).state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(c->status(live, false).samples_done(), at_checkpoint);
  EXPECT_EQ(c->status(waiting, false).state(), v1::JobStatus::QUEUED);
  EXPECT_EQ(c->counters().jobs_restored, before.size());
  // The old run's worker must register again, and its task of the old run counts no more.
  EXPECT_THROW(c->get_task(w), RequestError);
  EXPECT_FALSE(c->submit_result(render_task(in_flight, w)).accepted());
  const uint64_t w2 = worker();
  drain(w2);
  for (const std::string& id : {done, live, waiting}) {
    EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE) << id;
    EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr")))) << id;
    EXPECT_GT(c->image(id, true, false).exr().size(), 0u);
  }
  EXPECT_GT(c->image(cancelled, true, false).exr().size(), 0u);  // what was rendered stays
  restart(c, options(), &t);                                     // and once more, with everything ended
  for (const std::string& id : {done, live, waiting}) EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_THROW(c->cancel(waiting, "another", false), RequestError);  // owners are kept
  const std::string next = c->submit(request(s));
  EXPECT_EQ(c->list().back().id(), next);  // after the restored ones
}

// A crash after a job's last merge but before its end is on disk (its final checkpoint
// not yet renamed into place; here no checkpoint ever is): the restarted coordinator still
// has the scene and renders what the checkpoints lack. (The scene used to be deleted at
// the end in memory, and such a job came back FAILED, its scene lost.) The same for a
// sequence.
TEST_F(CoordinatorTest, ACrashBeforeTheEndIsRecordedKeepsTheScene) {
  const RenderSettings s = job_settings();
  CoordinatorOptions o = options();
  o.before_checkpoint_rename = [] { throw std::runtime_error("simulated crash before the rename"); };
  restart(c, o, &t);
  const std::string id = c->submit(request(s));
  v1::SubmitJobRequest seq = request(s);
  seq.add_frames(1);
  seq.add_frames(2);
  const std::string sequence = c->submit(seq);
  drain(worker());
  ASSERT_EQ(c->status(sequence, false).state(), v1::JobStatus::DONE);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);  // in memory; not on disk
  restart(c, options(), &t);
  for (const std::string& j : {id, sequence}) EXPECT_NE(c->status(j, false).state(), v1::JobStatus::FAILED) << j;
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(sequence, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // Recorded now: the scene goes, and another restart finds both ended.
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(sequence, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));
}

TEST_F(CoordinatorTest, ADamagedCheckpointRendersTheJobAgainAndAMissingSceneFailsIt) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string a = c->submit(request(s));
  RenderSettings other = s;
  other.seed = 9;  // a second job, with no checkpoint yet
  const std::string b = c->submit(request(other));
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const std::string cp = dir + "/jobs/" + a + "/checkpoint";
  ASSERT_TRUE(fs::exists(cp));
  {  // one byte flipped in the film
    std::string bytes = read_file_bytes(cp);
    bytes[bytes.size() / 2] ^= 0x10;
    write_file_atomic(cp, bytes);
  }
  restart(c, options(), &t);
  EXPECT_EQ(c->status(a, false).samples_done(), 0u);  // rendered again, from the start
  const uint64_t w2 = worker();
  drain(w2);
  EXPECT_EQ(c->status(a, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(a, "image.exr"))));
  EXPECT_TRUE(same_film_as_exr(local(other), read_exr(image_path(b, "image.exr"))));

  // A live job whose scene is gone from the data folder fails, saying why, without a path.
  const std::string c1 = c->submit(request(s));
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "scenes")) fs::remove_all(e.path());
  restart(c, options(), &t);
  const v1::JobStatus st = c->status(c1, false);
  EXPECT_EQ(st.state(), v1::JobStatus::FAILED);
  EXPECT_NE(st.error().find("scene is missing"), std::string::npos) << st.error();
  EXPECT_EQ(st.error().find(dir), std::string::npos) << st.error();
  restart(c, options(), &t);
  EXPECT_EQ(c->status(c1, false).state(), v1::JobStatus::FAILED);  // recorded
}

TEST_F(CoordinatorTest, ScenesOfEndedOrUnrecordedJobsAreNotKeptAcrossARestart) {
  const std::string a = c->submit(request(job_settings()));
  c->cancel(a);
  fs::create_directories(fs::path(dir) / "scenes" / "0123.staging-7");  // a crash mid-submit
  std::ofstream(fs::path(dir) / "scenes" / "feedfeedfeedfeedfeedfeedfeedfeed.bundle") << "x";
  restart(c, options(), &t);
  EXPECT_TRUE(fs::is_empty(fs::path(dir) / "scenes"));
}

TEST_F(CoordinatorTest, AStoppedCoordinatorSavesEveryResultItMerged) {
  const std::string a = c->submit(request(job_settings()));
  const uint64_t w = worker();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t merged = c->status(a, false).samples_done();
  c->checkpoint_all();  // what main does on SIGTERM
  restart(c, options(), &t);
  EXPECT_EQ(c->status(a, false).samples_done(), merged);
}

// ---- verify by replay -------------------------------------------------------------------

// Plausible sums that are not the render's: what a subtly broken or dishonest worker sends.
v1::TaskResult lie(v1::TaskResult r) {
  const size_t n = r.raw_size() / kBytesPerPixel;
  std::vector<PixelSums> sums = decode_sums(r.sums_zstd(), n);
  for (PixelSums& p : sums) p = PixelSums{p.r * 0.8, p.g * 0.8, p.b * 0.8, p.lum2 * 0.64, p.n};
  r.set_sums_zstd(encode_sums(sums));
  return r;
}

class VerifyTest : public CoordinatorTest {
 protected:
  void SetUp() override {}
  void start(double fraction) {
    CoordinatorOptions o = options();
    o.verify_fraction = fraction;
    c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  }
  uint64_t worker_as(const std::string& principal) {
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name(principal);
    return c->register_worker(r, principal).worker_id();
  }
  // One task for worker w, rendered (and falsified if `lying`) and returned; false if it
  // got none or is refused.
  bool step(uint64_t w, bool lying) {
    v1::GetTaskResponse r;
    try {
      r = c->get_task(w, 1);
    } catch (const RequestError&) {
      return false;
    }
    if (r.tasks_size() == 0) return false;
    const v1::TaskResult res = render_task(r.tasks(0), w);
    c->submit_result(lying ? lie(res) : res);
    return true;
  }
  // Both workers take turns until every job has ended; time moves on when neither has
  // work (expiring leases and checks nobody else can take).
  void run(uint64_t honest, uint64_t liar, bool lying) {
    for (int guard = 0; guard < 20000; ++guard) {
      bool any_live = false;
      for (const v1::JobStatus& j : c->list())
        any_live |= j.state() == v1::JobStatus::QUEUED || j.state() == v1::JobStatus::RUNNING;
      if (!any_live) return;
      const bool a = step(honest, false), b = step(liar, lying);
      if (!a && !b) {
        t += 11;
        c->expire_leases();
      }
    }
    FAIL() << "jobs did not end";
  }
};

TEST_F(VerifyTest, HonestWorkersPassEveryCheckAndTheImageIsUnchanged) {
  start(1.0);
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const double t0 = t;
  run(worker(), worker(), false);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  // Checks count in the workers' shares: the last ones are taken at once, and the job
  // never waits for a check to be skipped (time never had to move on).
  EXPECT_EQ(t, t0);
  const CoordinatorCounters k = c->counters();
  EXPECT_GT(k.checks_issued, 10u);
  EXPECT_EQ(k.checks_passed, k.checks_issued);
  EXPECT_EQ(k.checks_skipped, 0u);
  EXPECT_EQ(k.check_mismatches, 0u);
  EXPECT_EQ(k.workers_quarantined, 0u);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(VerifyTest, ALyingWorkerIsQuarantinedAndWhatItMergedIsRenderedAgain) {
  start(0.5);  // 27 tasks a job: the chance that no task of the liar's is checked is 2^-27
  const RenderSettings s = job_settings();
  RenderSettings other = s;
  other.seed = 17;
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string before = c->submit(request(other));
  run(honest, liar, false);  // the liar is honest at first: a job with its results ends DONE
  ASSERT_EQ(c->status(before, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->counters().workers_quarantined, 0u);
  const std::string id = c->submit(request(s));
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(step(liar, true));  // lies merged before anyone checks
  run(honest, liar, true);
  const CoordinatorCounters k = c->counters();
  EXPECT_EQ(k.workers_quarantined, 1u);
  EXPECT_GE(k.check_mismatches, 1u);
  EXPECT_GE(k.tiles_rendered_again, 3u);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  // Every lie it got merged was rendered again: the image is the honest one, bit for bit.
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // It gets no more work, and its token may not register again; the honest one goes on.
  EXPECT_THROW(c->get_task(liar), RequestError);
  EXPECT_THROW(worker_as("liar"), RequestError);
  EXPECT_NO_THROW(c->get_task(honest));
  // The job that ended before it was caught is flagged, not silently trusted.
  const std::string flag = c->status(before, false).error();
  EXPECT_NE(flag.find("quarantined"), std::string::npos) << flag;
  EXPECT_EQ(c->status(id, false).error(), "");
}

TEST_F(VerifyTest, AWorkerLyingOnlyAsTheCheckerIsTheOneQuarantined) {
  start(1.0);
  const RenderSettings s = job_settings();
  const uint64_t honest = worker_as("honest"), liar = worker_as("liar");
  const std::string id = c->submit(request(s));
  // The honest worker renders first; the liar gets only checks of its results, and lies.
  ASSERT_TRUE(step(honest, false));
  ASSERT_EQ(c->counters().checks_issued, 1u);
  // The liar's first task is the check of the honest worker's result (checks go first).
  const v1::GetTaskResponse r = c->get_task(liar, 1);
  ASSERT_EQ(r.tasks_size(), 1);
  c->submit_result(lie(render_task(r.tasks(0), liar)));
  EXPECT_EQ(c->counters().workers_quarantined, 1u);
  EXPECT_THROW(c->get_task(liar), RequestError);
  EXPECT_NO_THROW(c->get_task(honest));
  run(honest, honest, false);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

TEST_F(VerifyTest, NoChecksWithOneWorkerOrAZeroFraction) {
  start(0);
  const std::string id = c->submit(request(job_settings()));
  run(worker(), worker(), false);
  EXPECT_EQ(c->counters().checks_issued, 0u);
  start(1.0);
  const std::string alone = c->submit(request(job_settings()));
  const uint64_t w = worker();
  drain(w);
  EXPECT_EQ(c->status(alone, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->counters().checks_issued, 0u);
  (void)id;
}

// The autoscaling signal: what is left, in tasks, samples and core-seconds.
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

// ---- sequences -----------------------------------------------------------------------

class SequenceTest : public CoordinatorTest {
 protected:
  v1::SubmitJobRequest sequence(const std::vector<int>& frames) {
    v1::SubmitJobRequest r = request(job_settings());
    for (int f : frames) r.add_frames(f);
    return r;
  }
  RenderSettings frame(int n) const {
    RenderSettings s = job_settings();
    s.frame = n;
    return s;
  }
  bool frame_is_local(const std::string& id, int n) {
    const std::string path = dir + "/frame" + std::to_string(n) + ".exr";
    std::ofstream(path, std::ios::binary) << c->image(id, true, false, n).exr();
    const ExrImage img = read_exr(path);
    EXPECT_EQ(img.metadata.at("tessera/frame"), std::to_string(n));
    return same_film_as_exr(local(frame(n)), img);
  }
  std::map<int, v1::JobStatus::State> frame_states(const std::string& id) {
    std::map<int, v1::JobStatus::State> out;
    const v1::JobStatus st = c->status(id, false);
    for (const v1::FrameStatus& f : st.frames()) out[f.frame()] = f.state();
    return out;
  }
};

TEST_F(SequenceTest, EachFrameIsTheImageOfThatFrameAloneAndEarlierFramesGoFirst) {
  const std::string id = c->submit(sequence({7, 3, 5}));  // in the order given
  v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::QUEUED);
  EXPECT_EQ(st.frames_total(), 3u);
  EXPECT_EQ(st.frames_size(), 3);
  EXPECT_EQ(st.samples_total(), 3u * 48 * 36 * 10);
  EXPECT_EQ(st.tiles_total(), 3u * 9);  // counted without making a frame's film
  EXPECT_EQ(st.passes_total(), 3u);
  EXPECT_EQ(c->list().size(), 1u);  // the frames are in their sequence, not listed apart
  const uint64_t w = worker();
  std::vector<std::string> order;  // the job of each task, in the order handed out
  for (int guard = 0; guard < 1000; ++guard) {
    const v1::GetTaskResponse r = c->get_task(w);
    if (r.tasks_size() == 0) break;
    if (order.empty() || order.back() != r.tasks(0).job_id()) order.push_back(r.tasks(0).job_id());
    ASSERT_TRUE(c->submit_result(render_task(r.tasks(0), w)).accepted());
  }
  EXPECT_EQ(order, (std::vector<std::string>{id + "-f7", id + "-f3", id + "-f5"}));
  st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.frames_done(), 3u);
  EXPECT_EQ(st.samples_done(), st.samples_total());
  for (int n : {3, 5, 7}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  EXPECT_EQ(c->status(id + "-f5", false).sequence(), id);  // each frame's own job
  try {
    c->image(id);
    ADD_FAILURE() << "a sequence's image needs a frame";
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("--frame"), std::string::npos) << e.what();
  }
  EXPECT_THROW(c->image(id, true, false, 4), RequestError);  // not one of its frames
  EXPECT_THROW(c->cancel(id + "-f5"), RequestError);         // frames go with their sequence
}

TEST_F(SequenceTest, AWorkerWithRoomGetsTheNextFrameBeforeTheLastOneEnds) {
  const std::string id = c->submit(sequence({1, 2, 3, 4}));
  const uint64_t w = worker();
  // 9 tiles a frame: a worker asking for 20 tasks gets frame 1's and 2's first passes and
  // some of frame 3's, never waiting for frame 1 to finish.
  const v1::GetTaskResponse r = c->get_task(w, 20);
  ASSERT_EQ(r.tasks_size(), 20);
  std::map<std::string, int> per_job;
  for (const v1::Task& t : r.tasks()) ++per_job[t.job_id()];
  EXPECT_EQ(per_job[id + "-f1"], 9);
  EXPECT_EQ(per_job[id + "-f2"], 9);
  EXPECT_EQ(per_job[id + "-f3"], 2);
  const auto states = frame_states(id);
  EXPECT_EQ(states.at(1), v1::JobStatus::RUNNING);
  EXPECT_EQ(states.at(4), v1::JobStatus::QUEUED);  // not started: no film held for it
  for (const v1::Task& t : r.tasks()) ASSERT_TRUE(c->submit_result(render_task(t, w)).accepted());
  drain(w);
  for (int n : {1, 2, 3, 4}) EXPECT_TRUE(frame_is_local(id, n)) << n;
}

TEST_F(SequenceTest, CancelKeepsFinishedFrames) {
  const std::string id = c->submit(sequence({1, 2, 3}));
  const uint64_t w = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());  // a tile of frame 2
  const v1::JobStatus st = c->cancel(id);
  EXPECT_EQ(st.state(), v1::JobStatus::CANCELLED);
  const auto states = frame_states(id);
  EXPECT_EQ(states.at(1), v1::JobStatus::DONE);
  EXPECT_EQ(states.at(2), v1::JobStatus::CANCELLED);
  EXPECT_EQ(states.at(3), v1::JobStatus::CANCELLED);  // never started
  EXPECT_EQ(c->get_task(w).tasks_size(), 0);
  EXPECT_TRUE(frame_is_local(id, 1));
  EXPECT_GT(c->image(id, true, false, 2).exr().size(), 0u);  // what frame 2 had is kept
  EXPECT_THROW(c->image(id, true, false, 3), RequestError);
  // After a restart, as it was.
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(frame_states(id), states);
  EXPECT_TRUE(frame_is_local(id, 1));
}

TEST_F(SequenceTest, ARestartedCoordinatorGoesOnWithASequenceBitForBit) {
  const std::string id = c->submit(sequence({1, 2, 3}), "someone");
  const uint64_t w = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  for (int k = 0; k < 4; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;  // the next merge writes frame 2's checkpoint
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t at_checkpoint = c->status(id, false).samples_done();
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());  // lost in the crash

  restart(c, options(), &t);
  v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.owner(), "someone");
  EXPECT_EQ(st.samples_done(), at_checkpoint);
  EXPECT_EQ(frame_states(id).at(1), v1::JobStatus::DONE);
  EXPECT_EQ(frame_states(id).at(3), v1::JobStatus::QUEUED);
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int n : {1, 2, 3}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int n : {1, 2, 3}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));  // the ended sequence's scene is gone
}

// A restart can bring a sequence back with a gap: frames 1 and 3 have checkpoints, frame 2
// (started, but killed before its first checkpoint) has none. Its load is then the two
// restored frames' samples left plus one whole frame, not two: the admission limit
// double-counted frame 3 (a bug of the three load formulas that disagreed).
TEST_F(SequenceTest, ASequenceRestoredWithAGapInItsFramesIsCountedOnce) {
  const std::string id = c->submit(sequence({1, 2, 3}), "someone");
  const uint64_t w = worker();
  const v1::GetTaskResponse r = c->get_task(w, 27);  // every frame's first pass: all three start
  ASSERT_EQ(r.tasks_size(), 27);
  std::set<std::string> merged;
  for (const v1::Task& task : r.tasks())
    if (merged.insert(task.job_id()).second) ASSERT_TRUE(c->submit_result(render_task(task, w)).accepted());
  ASSERT_EQ(merged.size(), 3u);
  c->checkpoint_all();
  fs::remove(dir + "/jobs/" + id + "-f2/checkpoint");  // frame 2 never reached its first checkpoint
  restart(c, options(), &t);
  EXPECT_EQ(frame_states(id).at(2), v1::JobStatus::QUEUED);
  const uint64_t frame = 48 * 36 * 10, tile_pass = 16 * 16 * 4;
  const uint64_t left = 2 * (frame - tile_pass) + frame;
  EXPECT_EQ(c->queue().samples_remaining, left);
  // A still of one frame's samples fits exactly under a limit of what is left plus it.
  CoordinatorOptions o = options();
  o.max_queued_samples_per_client = left + frame;
  restart(c, o, &t);
  EXPECT_NO_THROW(c->submit(request(job_settings()), "someone"));
  EXPECT_THROW(c->submit(request(job_settings()), "someone"), RequestError);
}

TEST_F(SequenceTest, AFrameFailingOnTwoWorkersFailsTheSequenceAndKeepsTheFinishedFrames) {
  const std::string id = c->submit(sequence({1, 2}));
  const uint64_t a = worker(), b = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(a).tasks(0), a)).accepted());
  c->release(a, c->get_task(a).tasks(0).task_id(), "scene does not load here");
  c->release(b, c->get_task(b).tasks(0).task_id(), "scene does not load here");
  const v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::FAILED);
  EXPECT_NE(st.error().find("frame 2"), std::string::npos) << st.error();
  EXPECT_TRUE(frame_is_local(id, 1));
}

// A submit the job database cannot record is refused (a still and a sequence alike), its
// scene is not kept, and nothing is left running.
TEST_F(SequenceTest, ASubmitTheDatabaseCannotRecordIsRefused) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir + "/coordinator.db").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "DROP TABLE jobs", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  for (const v1::SubmitJobRequest& r : {request(job_settings()), sequence({1, 2})}) {
    try {
      c->submit(r);
      ADD_FAILURE() << "accepted";
    } catch (const RequestError& e) {
      EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
      EXPECT_NE(std::string(e.what()).find("the coordinator cannot record the job"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(c->list().empty());
  EXPECT_EQ(c->counters().jobs_refused, 2u);
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));
}

TEST_F(SequenceTest, BadFrameListsAreRefusedNamingTheProblem) {
  auto refused = [&](const v1::SubmitJobRequest& r, const std::string& part) {
    try {
      c->submit(r);
      ADD_FAILURE() << "accepted";
    } catch (const RequestError& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  refused(sequence({1, 2, 1}), "frame 1 given twice");
  refused(sequence({1, 2000000}), "frame 2000000 out of range");
  v1::SubmitJobRequest r = sequence({1, 2});
  r.mutable_settings()->set_frame(4);
  refused(r, "frame number");
  EXPECT_TRUE(c->list().empty());
}

}  // namespace
}  // namespace tessera
