// The coordinator's parts wired as Coordinator's constructor wires them (coordinator.cc),
// for testing each unit's rules on their own: no gRPC, no clock (`now` is passed
// explicitly), no disk. Jobs go straight into the JobTable (a Job needs only its
// RenderSettings, not a scene), and results carry fabricated sums that FramePlan::check
// finds plausible, encoded as a worker encodes them.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "proto/wire.h"
#include "server/dispatcher.h"
#include "server/effects.h"
#include "server/options.h"
#include "server/request_error.h"
#include "server/result_intake.h"
#include "server/worker_lifecycle.h"

namespace tessera::testing {

// As coordinator_test's job_settings(): 48 x 36 pixels in 16-pixel tiles (3 x 3 = 9
// tiles, the bottom row 4 pixels high), 10 samples a pixel in passes of 4, 4 and 2.
inline RenderSettings small_settings() {
  RenderSettings s;
  s.camera.width = 48;
  s.camera.height = 36;
  s.spp = 10;
  s.pass_spp = 4;
  s.max_depth = 6;
  s.seed = 3;
  s.tile_size = 16;
  // The parts are tested on the film's sums alone (a frame that may trace light paths
  // weighs its splat film too: CoordinatorTest.AFrameWithAovsWeighsItsAovSumsAgainstTheLivePixels).
  s.light_tracer = RenderSettings::LightTracer::kOff;
  return s;
}
constexpr uint32_t kTiles = 9, kPasses = 3;
constexpr uint64_t kPixels = 48 * 36;
constexpr uint64_t kSamples = kPixels * 10;      // of one frame
constexpr uint64_t kFirstPassSamples = 256 * 4;  // of a full tile's first task

inline CoordinatorOptions parts_options() {
  CoordinatorOptions o;
  o.data_dir = "/srv/tessera-data";  // never touched: no part writes to disk
  o.lease_seconds = 5;
  o.image_interval_seconds = 5;
  o.checkpoint_seconds = 5;
  o.verify_fraction = 0;  // picks are random: tests pick a task by setting its Lease::task
  return o;
}

inline bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

template <typename T>
bool contains(const std::vector<T>& v, const T& x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

// Runs f, which must throw RequestError with `code`; returns its message for the test
// to read.
template <typename F>
std::string refusal(F&& f, RequestError::Code code) {
  try {
    f();
  } catch (const RequestError& e) {
    EXPECT_EQ(int(e.code()), int(code)) << e.what();
    return e.what();
  }
  ADD_FAILURE() << "not refused";
  return "";
}

// Sums of one pass of one tile that FramePlan::check accepts: every pixel has n = the
// pass's length, r = g = b = n v and lum2 = n v^2, a constant luminance v per sample (the
// luminance weights add to 1): Cauchy-Schwarz holds with equality. v = value + pixel / 1024,
// so that tiles and values give different digests.
inline std::vector<PixelSums> plausible_sums(const FramePlan& plan, uint32_t tile, uint32_t pass, double value = 0.5) {
  const uint32_t n = plan.passes()[pass].second - plan.passes()[pass].first;
  std::vector<PixelSums> sums(size_t(plan.tiles()[tile].area()));
  for (size_t i = 0; i < sums.size(); ++i) {
    const double v = value + double(i) / 1024;
    sums[i] = PixelSums{n * v, n * v, n * v, n * v * v, n};
  }
  return sums;
}

// A worker's result for (tile, pass) of the plan under `task`, as the worker encodes it.
inline v1::TaskResult result_for(const FramePlan& plan, uint32_t tile, uint32_t pass, uint64_t task, uint64_t worker,
                                 double value = 0.5) {
  const std::vector<PixelSums> sums = plausible_sums(plan, tile, pass, value);
  v1::TaskResult r;
  r.set_worker_id(worker);
  r.set_task_id(task);
  r.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
  r.set_sums_zstd(encode_sums(sums));
  uint64_t samples = 0;
  for (const PixelSums& p : sums) samples += p.n;
  r.set_samples(samples);
  r.set_render_seconds(0.01);
  return r;
}

// Merges the first `passes` passes of every tile into the plan directly (no leases).
inline void merge_passes(FramePlan& plan, uint32_t passes) {
  for (uint32_t p = 0; p < passes; ++p)
    for (uint32_t t = 0; t < plan.tiles().size(); ++t)
      if (plan.wants(t, p)) {
        ASSERT_EQ(plan.merge(t, p, plausible_sums(plan, t, p)), FramePlan::Merge::kMerged);
      }
}

class PartsTest : public ::testing::Test {
 protected:
  explicit PartsTest(CoordinatorOptions o = parts_options())
      : options(std::move(o)),
        snapshotter(options.image_interval_seconds, options.checkpoint_seconds),
        leases(uint64_t(1) << 40),  // generation 1's task ids
        leasing(leases, jobs, workers, checks, counters, options.lease_seconds),
        lifecycle(jobs, leasing, snapshotter, counters),
        sequences(jobs, lifecycle),
        verifier(options.verify_fraction, options.lease_seconds, checks, jobs, leasing, workers, lifecycle, counters),
        dispatcher({jobs, leases, leasing, workers, checks, verifier, sequences, lifecycle}, options.max_live_pixels,
                   options.max_leases_per_worker),
        intake({jobs, leases, leasing, workers, verifier, lifecycle, snapshotter, counters}),
        worker_lifecycle({workers, jobs, leases, leasing, checks, lifecycle, counters}, options) {}

  const CoordinatorOptions options;
  double now = 1000;
  const Snapshotter snapshotter;
  // The farm's state.
  JobTable jobs;
  LeaseTable leases;
  WorkerRegistry workers;
  CheckBook checks;
  CoordinatorCounters counters;
  // The units acting on it.
  Leasing leasing;
  JobLifecycle lifecycle;
  SequenceScheduler sequences;
  Verifier verifier;
  Dispatcher dispatcher;
  ResultIntake intake;
  WorkerLifecycle worker_lifecycle;
  Effects fx;  // what the operations leave for after the lock

  JobMeta meta(const RenderSettings& s, const std::string& owner, int32_t priority) {
    JobMeta m;
    m.id = jobs.new_id();
    m.name = "job " + m.id;
    m.owner = owner;
    m.scene_hash = "scene-" + m.id;
    m.main_file = "scene.dae";
    m.priority = priority;
    m.seq = jobs.next_seq();
    m.scene_bytes = 1000;
    m.settings = to_proto(s);
    return m;
  }
  // A still, as Coordinator::submit adds it.
  std::shared_ptr<Job> add_still(const RenderSettings& s = small_settings(), const std::string& owner = "",
                                 int32_t priority = 0) {
    auto job = std::make_shared<Job>(meta(s, owner, priority), s);
    job->submitted = job->snaps.last_checkpoint = now;
    jobs.add(job);
    return job;
  }
  Sequence& add_sequence(const std::vector<int>& frames, const RenderSettings& s = small_settings(),
                         const std::string& owner = "", int32_t priority = 0) {
    auto sq = std::make_shared<Sequence>(meta(s, owner, priority), s, frames);
    sq->submitted = now;
    return jobs.add(std::move(sq));
  }
  // Frames started out of order, as Recovery leaves a sequence whose checkpoints have a
  // gap: `next` at the first frame not started.
  void restore_frames(Sequence& s, const std::vector<size_t>& started) {
    for (size_t i : started) {
      s.jobs[i] = SequenceScheduler::make_frame(s, i);
      jobs.add(s.jobs[i]);
      ++s.frames_started;
      ++s.live_frames;
    }
    while (s.next < s.jobs.size() && s.jobs[s.next]) ++s.next;
  }
  // A frame's job started as the Dispatcher starts it.
  Job& start_frame(Sequence& s) {
    Job* j = sequences.start_next(s, now, fx);
    if (!j) throw std::logic_error("sequence " + s.id() + " has no frame to start");
    return *j;
  }

  uint64_t add_worker(uint32_t threads = 1, const std::string& principal = "") {
    WorkerInfo& w = workers.add(principal.empty() ? "worker" : principal, threads, now);
    w.principal = principal;
    return w.id;
  }
  WorkerInfo& worker(uint64_t id) {
    WorkerInfo* w = workers.find(id);
    if (!w) throw std::logic_error("no worker " + std::to_string(id));
    return *w;
  }

  // The job's next ready task leased to the worker as the Dispatcher leases it; its id.
  uint64_t lease_next(Job& job, uint64_t w) {
    const std::optional<TileTask> t = job.plan.take();
    if (!t) throw std::logic_error("job " + job.id() + " has no ready task");
    const uint64_t id = leasing.grant(job, *t, worker(w), now);
    lifecycle.start(job, now, fx);
    return id;
  }
  // The result of a known lease, from its holder (or of one known when results were last
  // submitted: a lease whose passes merged is known by its id alone).
  v1::TaskResult result(uint64_t task, double value = 0.5) const {
    const Lease* l = leases.known(task);
    if (!l && seen_.count(task)) l = &seen_.at(task);
    if (!l) throw std::logic_error("no lease " + std::to_string(task));
    return result_for(jobs.job(l->job).plan, l->tile, l->pass, task, l->worker, value);
  }
  // Results as SubmitResults takes them: screened, decoded, merged; one ack each.
  std::vector<v1::ResultAck> submit(const std::vector<v1::TaskResult>& results) {
    for (const auto& [id, l] : leases.live_leases()) seen_[id] = l;
    std::vector<const v1::TaskResult*> batch;
    for (const v1::TaskResult& r : results) batch.push_back(&r);
    ResultIntake::Batch b = intake.screen(batch);
    for (size_t first = 0, last; first < b.incoming.size(); first = last) {  // as Coordinator::submit_results
      last = ResultIntake::slice_end(b, first);
      ResultIntake::decode(b, first, last);
      intake.merge(b, first, last, now, fx);
      ResultIntake::free_decoded(b, first, last);
    }
    return b.acks;
  }
  v1::ResultAck submit(const v1::TaskResult& r) { return submit(std::vector<v1::TaskResult>{r})[0]; }
  // Every task of the job leased to the worker and its result merged, one at a time.
  void render_all(Job& job, uint64_t w) {
    while (job.live() && job.plan.ready() > 0) ASSERT_TRUE(submit(result(lease_next(job, w))).accepted());
  }

 private:
  std::map<uint64_t, Lease> seen_;  // every lease live when results were submitted

 protected:
};

// One still and two workers, what most rules need.
class OneJobTest : public PartsTest {
 protected:
  std::shared_ptr<Job> job = add_still();
  uint64_t a = add_worker(), b = add_worker();
};

}  // namespace tessera::testing
