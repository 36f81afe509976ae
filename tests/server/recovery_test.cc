// Recovery: a restarted coordinator takes up every job where its last checkpoint left it,
// from the JobStore's rows and checkpoints (here a MemoryJobStore; the scene's restore a
// lambda).
#include "server/recovery.h"

#include <gtest/gtest.h>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::contains;
using testing::kPixels;
using testing::kTiles;
using testing::merge_passes;
using testing::small_settings;
constexpr auto QUEUED = v1::JobStatus::QUEUED, RUNNING = v1::JobStatus::RUNNING, DONE = v1::JobStatus::DONE,
               FAILED = v1::JobStatus::FAILED;

class RecoveryTest : public testing::PartsTest {
 protected:
  MemoryJobStore store;
  std::string lost;  // non-empty: the scene is gone, for this reason
  int scenes_restored = 0;

  // The frame passes each job's image on disk holds (none: not listed).
  std::map<std::string, uint32_t> images;

  void restore() {
    const auto restore_scene = [this](const std::string&) -> uint64_t {
      if (!lost.empty()) throw std::runtime_error(lost);
      ++scenes_restored;
      return 4321;
    };
    const auto image_passes = [this](const std::string& job) -> std::optional<uint32_t> {
      if (!images.count(job)) return std::nullopt;
      return images.at(job);
    };
    Recovery({store, jobs, lifecycle, snapshotter, counters, restore_scene, image_passes}).restore(now, fx);
  }
  // A job's row as the earlier run left it.
  StoredJob row(uint64_t seq, v1::JobStatus::State state, const std::vector<int>& frames = {}) {
    StoredJob r;
    r.meta.id = "job" + std::to_string(seq);
    r.meta.name = r.meta.id;
    r.meta.scene_hash = "scene";
    r.meta.seq = seq;
    r.meta.settings = to_proto(small_settings());
    r.state = state;
    r.frames = frames;
    store.add(r);
    return r;
  }
  // The bytes of a checkpoint of a plan with `passes` frame passes merged.
  static std::string checkpoint_bytes(uint32_t passes, double elapsed, std::optional<int> frame = std::nullopt) {
    RenderSettings s = small_settings();
    s.frame = frame;
    FramePlan plan(s);
    merge_passes(plan, passes);
    return encode_checkpoint(plan, elapsed);
  }
  // The job's checkpoint as the earlier run wrote it.
  void checkpoint(const std::string& id, uint32_t passes, double elapsed, std::optional<int> frame = std::nullopt) {
    store.set_checkpoint_bytes(id, checkpoint_bytes(passes, elapsed, frame));
  }
};

// The frame passes of a plan with every pass merged (what a DONE job's final image holds).
uint32_t all_frame_passes() {
  FramePlan plan(small_settings());
  merge_passes(plan, testing::kPasses);
  return plan.frame_passes_done();
}

TEST_F(RecoveryTest, AnEndedJobComesBackAsOnDiskWithoutItsFilm) {
  StoredJob r = row(1, DONE);
  store.end(r.meta.id, DONE, "", 7);
  checkpoint(r.meta.id, testing::kPasses, 7);
  images[r.meta.id] = all_frame_passes();  // its final image, whole
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), DONE);
  EXPECT_FALSE(job.plan.has_film());  // its image is on disk: start-up decodes no film
  EXPECT_TRUE(job.plan.done());
  EXPECT_EQ(job.plan.samples_merged(), testing::kSamples);
  EXPECT_EQ(job.started, now - 7);
  EXPECT_EQ(job.finished_at, now);
  EXPECT_TRUE(job.end_recorded);
  // Its image and checkpoint are written: nothing to write again.
  EXPECT_EQ(job.written.images, 1u);
  EXPECT_EQ(job.written.image_merges, job.plan.merges());
  EXPECT_EQ(job.written.checkpoint_merges, job.plan.merges());
  EXPECT_TRUE(Snapshotter::image_current(job, false, job.plan.merges()));
  EXPECT_EQ(scenes_restored, 0);  // an ended job needs no scene
  EXPECT_TRUE(fx.writes.empty());
  EXPECT_EQ(counters.jobs_restored, 1u);
}

// Its end recorded, its final image not written (a full disk): the film is read back from
// the checkpoint and the image written again; the job stays until it is.
TEST_F(RecoveryTest, ADoneJobWithoutItsFinalImageIsWrittenAgainFromItsCheckpoint) {
  StoredJob r = row(1, DONE);
  store.end(r.meta.id, DONE, "", 7);
  checkpoint(r.meta.id, testing::kPasses, 7);
  images[r.meta.id] = all_frame_passes() - 1;  // a progressive image
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), DONE);
  EXPECT_TRUE(job.plan.has_film());
  EXPECT_TRUE(job.plan.done());
  EXPECT_TRUE(job.end_recorded);
  EXPECT_FALSE(Snapshotter::image_current(job, false, job.plan.merges()));
  ASSERT_EQ(fx.writes.size(), 1u);
  EXPECT_EQ(fx.writes[0].get(), &job);
}

TEST_F(RecoveryTest, ALiveJobWithACheckpointGoesOnRunningWithItsMerges) {
  const StoredJob r = row(1, QUEUED);
  checkpoint(r.meta.id, 1, 3);
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), RUNNING);
  EXPECT_EQ(job.plan.merges(), kTiles);
  EXPECT_EQ(job.plan.samples_merged(), kPixels * 4);
  EXPECT_EQ(job.plan.ready(), kTiles);  // every tile's second pass
  EXPECT_EQ(job.started, now - 3);
  EXPECT_EQ(job.meta.scene_bytes, 4321u);  // counted again from the bundle
  EXPECT_EQ(scenes_restored, 1);
  EXPECT_EQ(job.snaps.checkpoint_merges, kTiles);  // no checkpoint due before it merges more
  EXPECT_TRUE(fx.writes.empty());
}

TEST_F(RecoveryTest, ALiveJobWithoutACheckpointStartsOverQueued) {
  const StoredJob r = row(1, RUNNING);
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), QUEUED);
  EXPECT_EQ(job.plan.merges(), 0u);
  EXPECT_EQ(job.plan.ready(), kTiles);
}

TEST_F(RecoveryTest, ADamagedCheckpointMeansTheJobStartsOver) {
  const StoredJob r = row(1, RUNNING);
  std::string bytes = checkpoint_bytes(2, 3);
  bytes[bytes.size() / 2] ^= 0x10;
  store.set_checkpoint_bytes(r.meta.id, bytes);
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), QUEUED);
  EXPECT_EQ(job.plan.merges(), 0u);
  EXPECT_EQ(job.plan.samples_merged(), 0u);
  EXPECT_EQ(job.plan.ready(), kTiles);
}

TEST_F(RecoveryTest, ALostSceneFailsTheJobKeepingItsImage) {
  const StoredJob r = row(1, RUNNING);
  checkpoint(r.meta.id, 1, 3);
  lost = "its scene is missing from the data folder";
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), FAILED);
  EXPECT_EQ(job.error, "cannot go on after the coordinator restarted: its scene is missing from the data folder");
  EXPECT_TRUE(contains(fx.writes, jobs.shared(r.meta.id)));
  EXPECT_EQ(job.plan.merges(), kTiles);  // what was rendered is in its final image
}

TEST_F(RecoveryTest, AJobDoneButNotRecordedEndsDone) {
  // The crash came between its last checkpoint and recording its end.
  const StoredJob r = row(1, RUNNING);
  checkpoint(r.meta.id, testing::kPasses, 9);
  restore();
  Job& job = jobs.job(r.meta.id);
  EXPECT_EQ(job.state(), DONE);
  EXPECT_TRUE(contains(fx.writes, jobs.shared(r.meta.id)));
  EXPECT_EQ(job.started, now - 9);
}

TEST_F(RecoveryTest, SubmissionOrderGoesOnPastTheRestoredJobs) {
  row(7, DONE);
  row(3, QUEUED);
  restore();
  EXPECT_EQ(jobs.next_seq(), 8u);
  EXPECT_EQ(counters.jobs_restored, 2u);
}

TEST_F(RecoveryTest, ASequenceWithAGapInItsCheckpointsGoesOnAtTheGap) {
  const StoredJob r = row(1, RUNNING, {10, 11, 12, 13});
  checkpoint(r.meta.id + "-f10", 1, 2, 10);
  checkpoint(r.meta.id + "-f12", 2, 5, 12);  // started after 11, whose checkpoint is missing
  restore();
  Sequence& s = *jobs.find_sequence(r.meta.id);
  EXPECT_EQ(s.state(), RUNNING);
  EXPECT_EQ(s.next, 1u);  // frame 11 starts next
  EXPECT_EQ(s.frames_started, 2u);
  EXPECT_EQ(s.live_frames, 2u);
  EXPECT_EQ(s.jobs[1], nullptr);
  ASSERT_NE(s.jobs[2], nullptr);
  EXPECT_EQ(s.jobs[2]->plan.merges(), 2 * kTiles);
  EXPECT_EQ(s.jobs[2]->state(), RUNNING);
  EXPECT_EQ(s.started, now - 5);
  EXPECT_EQ(s.meta.scene_bytes, 4321u);
  EXPECT_EQ(jobs.find_job(r.meta.id + "-f12"), s.jobs[2].get());
  // Frame 11 starts next; then 13 (12 is not started twice).
  EXPECT_EQ(start_frame(s).frame_index, 1u);
  EXPECT_EQ(start_frame(s).frame_index, 3u);
  EXPECT_EQ(sequences.start_next(s, now, fx), nullptr);
}

TEST_F(RecoveryTest, ASequenceWhoseEveryFrameIsDoneEndsDone) {
  const StoredJob r = row(1, RUNNING, {1, 2});
  checkpoint(r.meta.id + "-f1", testing::kPasses, 2, 1);
  checkpoint(r.meta.id + "-f2", testing::kPasses, 3, 2);
  restore();
  Sequence& s = *jobs.find_sequence(r.meta.id);
  EXPECT_EQ(s.state(), DONE);
  EXPECT_EQ(s.frames_done, 2u);
  EXPECT_EQ(fx.writes.size(), 2u);  // each frame's image written again, in case it was not
}

// A finished frame whose image on disk holds its every pass is not written again, and its
// film is not read: a restart held a film per finished frame at once. One whose image
// holds fewer passes (the crash came between its checkpoint and its image), or has none,
// is written again from its film.
TEST_F(RecoveryTest, OnlyFinishedFramesWithoutTheirWholeImageAreWrittenAgain) {
  const StoredJob r = row(1, RUNNING, {1, 2, 3, 4});
  for (int f = 1; f <= 3; ++f) checkpoint(r.meta.id + "-f" + std::to_string(f), testing::kPasses, 2, f);
  FramePlan whole(small_settings());
  merge_passes(whole, testing::kPasses);
  images[r.meta.id + "-f1"] = whole.frame_passes_done();
  images[r.meta.id + "-f2"] = whole.frame_passes_done() - 1;  // an earlier snapshot's
  restore();
  Sequence& s = *jobs.find_sequence(r.meta.id);
  EXPECT_EQ(s.state(), RUNNING);
  EXPECT_EQ(s.frames_done, 3u);
  ASSERT_EQ(fx.writes.size(), 2u);
  std::set<std::string> written;
  for (const auto& job : fx.writes) written.insert(job->id());
  EXPECT_EQ(written, (std::set<std::string>{r.meta.id + "-f2", r.meta.id + "-f3"}));
  EXPECT_EQ(s.jobs[0], nullptr);  // left memory, its film never read
}

TEST_F(RecoveryTest, AnEndedSequenceComesBackRecorded) {
  const StoredJob r = row(1, RUNNING, {1, 2});
  store.end(r.meta.id, v1::JobStatus::CANCELLED, "", 4);
  checkpoint(r.meta.id + "-f1", 1, 2, 1);
  restore();
  Sequence& s = *jobs.find_sequence(r.meta.id);
  EXPECT_EQ(s.state(), v1::JobStatus::CANCELLED);
  EXPECT_TRUE(s.end_recorded);
  EXPECT_EQ(s.jobs[0]->state(), v1::JobStatus::CANCELLED);
  EXPECT_FALSE(s.jobs[0]->plan.has_film());
  EXPECT_EQ(scenes_restored, 0);
  EXPECT_FALSE(lifecycle.sequence_end_due(r.meta.id));
}

TEST_F(RecoveryTest, ASequenceWhoseSceneIsLostFails) {
  const StoredJob r = row(1, RUNNING, {1, 2});
  checkpoint(r.meta.id + "-f1", 1, 2, 1);
  lost = "its scene in the data folder is damaged";
  restore();
  Sequence& s = *jobs.find_sequence(r.meta.id);
  EXPECT_EQ(s.state(), FAILED);
  EXPECT_EQ(s.error, "cannot go on after the coordinator restarted: its scene in the data folder is damaged");
  EXPECT_EQ(s.jobs[0]->state(), v1::JobStatus::CANCELLED);
  EXPECT_TRUE(contains(fx.writes, s.jobs[0]));  // it keeps what it rendered
}

}  // namespace
}  // namespace tessera
