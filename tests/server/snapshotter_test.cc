// Snapshotter decides when a progressive image or checkpoint is due and copies the film
// under the lock; SnapshotWriter writes it outside the lock, newest wins, and records a
// job's end once disk holds it.
#include "server/snapshotter.h"

#include <gtest/gtest.h>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::has;
using testing::merge_passes;
using R = SnapshotOutcome::Result;

class SnapshotterTest : public testing::PartsTest {
 protected:
  std::shared_ptr<Job> job = add_still();
};

TEST_F(SnapshotterTest, NothingIsDueRightAfterTheSubmit) {
  EXPECT_FALSE(snapshotter.after_merge(job, now));  // no frame pass, no checkpoint interval
  EXPECT_FALSE(snapshotter.after_merge(job, now + options.checkpoint_seconds - 0.001));
}

TEST_F(SnapshotterTest, AnImageNeedsANewFramePassAndItsInterval) {
  merge_passes(job->plan, 1);
  std::optional<ImageSnapshot> snap = snapshotter.after_merge(job, now);
  ASSERT_TRUE(snap);  // the first frame pass: the first image is never late
  EXPECT_TRUE(snap->image);
  EXPECT_FALSE(snap->checkpoint);
  EXPECT_EQ(job->snaps.image_frame_passes, 1u);
  EXPECT_EQ(job->snaps.last_image, now);
  // The same frame pass: no other image, however long after (short of a checkpoint).
  EXPECT_FALSE(snapshotter.after_merge(job, now + options.checkpoint_seconds - 0.001));
  merge_passes(job->plan, 2);  // a new frame pass, before the image interval passed
  const double at = now + options.image_interval_seconds;
  ASSERT_EQ(options.image_interval_seconds, options.checkpoint_seconds);
  EXPECT_FALSE(snapshotter.after_merge(job, at - 0.001));
  snap = snapshotter.after_merge(job, at);
  ASSERT_TRUE(snap);
  EXPECT_TRUE(snap->image);
  EXPECT_TRUE(snap->checkpoint);  // its interval passed too
  EXPECT_EQ(job->snaps.image_frame_passes, 2u);
}

TEST_F(SnapshotterTest, WithoutANewFramePassOnlyACheckpointIsDue) {
  merge_passes(job->plan, 1);
  ASSERT_TRUE(snapshotter.after_merge(job, now));
  const std::optional<ImageSnapshot> snap = snapshotter.after_merge(job, now + options.checkpoint_seconds);
  ASSERT_TRUE(snap);
  EXPECT_FALSE(snap->image);
  EXPECT_TRUE(snap->checkpoint);
  EXPECT_EQ(job->snaps.last_checkpoint, now + options.checkpoint_seconds);
}

TEST_F(SnapshotterTest, SlowWritesStretchTheIntervalsToKeepTheirShare) {
  // The last image took 1 s and the last checkpoint 0.5 s to write: they may come every
  // kWriteShare x 1 = 20 s and kWriteShare x 0.5 = 10 s, not every 5 s.
  job->snaps.image_write_seconds = 1;
  job->snaps.checkpoint_write_seconds = 0.5;
  job->snaps.last_image = now;
  merge_passes(job->plan, 1);
  const double image_every = Snapshotter::kWriteShare * 1, checkpoint_every = Snapshotter::kWriteShare * 0.5;
  ASSERT_GT(checkpoint_every, options.checkpoint_seconds);
  EXPECT_FALSE(snapshotter.after_merge(job, now + checkpoint_every - 0.001));
  std::optional<ImageSnapshot> snap = snapshotter.after_merge(job, now + checkpoint_every);
  ASSERT_TRUE(snap);
  EXPECT_FALSE(snap->image);
  EXPECT_TRUE(snap->checkpoint);
  snap = snapshotter.after_merge(job, now + image_every);
  ASSERT_TRUE(snap);
  EXPECT_TRUE(snap->image);
}

TEST_F(SnapshotterTest, TakeCopiesTheFilmIntoTheSpareFilm) {
  merge_passes(job->plan, 1);
  lifecycle.start(*job, now - 3);
  const Film* spare = job->snaps.spare_film.get();
  ASSERT_NE(spare, nullptr);
  const ImageSnapshot snap = snapshotter.take(job, true, true, now);
  EXPECT_EQ(snap.film.get(), spare);  // no new film: its pages are mapped already
  EXPECT_EQ(job->snaps.spare_film, nullptr);
  ASSERT_EQ(snap.film->pixels().size(), job->plan.film().pixels().size());
  for (size_t i = 0; i < snap.film->pixels().size(); ++i)
    ASSERT_EQ(snap.film->pixels()[i].r, job->plan.film().pixels()[i].r) << i;
  EXPECT_EQ(snap.seq, 1u);
  EXPECT_EQ(snap.merges, job->plan.merges());
  EXPECT_EQ(snap.plan.merges, job->plan.merges());  // with a checkpoint, the plan's state
  EXPECT_EQ(snap.elapsed, 3);
  EXPECT_FALSE(snap.ended);
  EXPECT_EQ(snap.meta.at("job"), job->id());
  EXPECT_EQ(snap.meta.at("frame_passes"), "1");
  EXPECT_EQ(snap.meta.count("frame"), 0u);  // a still
  const ImageSnapshot next = snapshotter.take(job, true, false, now);
  EXPECT_NE(next.film, nullptr);  // a new film when the spare is out
  EXPECT_EQ(next.seq, 2u);
}

TEST_F(SnapshotterTest, AFramesSnapshotNamesItsFrameAndTime) {
  Sequence& s = add_sequence({48});
  const std::shared_ptr<Job> frame = jobs.shared(start_frame(s).id());
  const ImageSnapshot snap = snapshotter.take(frame, true, false, now);
  EXPECT_EQ(snap.meta.at("frame"), "48");
  EXPECT_EQ(snap.meta.at("time"), std::to_string(48 / 24.0));  // frame / fps
}

TEST_F(SnapshotterTest, WrittenAppliesTheOutcomeAndCountsIt) {
  ImageSnapshot snap = snapshotter.take(job, true, true, now);
  SnapshotOutcome out;
  out.image = R::kFailed;
  out.image_why = "disk full";
  out.checkpoint = R::kWritten;
  out.checkpoint_seconds = 0.25;
  snapshotter.written(snap, out, counters);
  EXPECT_EQ(job->image_error, "disk full");
  EXPECT_EQ(job->checkpoint_error, "");
  EXPECT_EQ(job->snaps.checkpoint_write_seconds, 0.25);
  EXPECT_EQ(counters.image_errors, 1u);
  EXPECT_EQ(counters.checkpoints_written, 1u);
  EXPECT_NE(job->snaps.spare_film, nullptr);  // a live job keeps the film for the next copy
  snap = snapshotter.take(job, true, false, now);
  out = {};
  out.image = R::kWritten;
  out.image_seconds = 0.5;
  snapshotter.written(snap, out, counters);
  EXPECT_EQ(job->image_error, "");  // cleared by the next write
  EXPECT_EQ(job->snaps.image_write_seconds, 0.5);
  EXPECT_EQ(counters.images_written, 1u);
}

TEST_F(SnapshotterTest, AnEndedJobsFilmIsReleasedOnlyWhenDiskHoldsItAll) {
  lifecycle.end(*job, v1::JobStatus::CANCELLED, now, fx);
  ImageSnapshot snap = snapshotter.take(job, true, true, now);
  snapshotter.written(snap, SnapshotOutcome{}, counters);
  EXPECT_TRUE(job->plan.has_film());
  snap = snapshotter.take(job, true, true, now);
  SnapshotOutcome out;
  out.release_film = true;
  snapshotter.written(snap, out, counters);
  EXPECT_FALSE(job->plan.has_film());
  EXPECT_EQ(snapshotter.take(job, true, true, now).film, nullptr);  // nothing left to write
}

// ---- SnapshotWriter, over MemoryImageSink and MemoryJobStore ----

class SnapshotWriterTest : public SnapshotterTest {
 protected:
  MemoryImageSink sink;
  MemoryJobStore store;
  std::vector<std::string> released;  // scenes whose use ended
  SnapshotWriter writer{
      sink, store, {[this](const std::string& h) { released.push_back(h); }, nullptr, options.data_dir}};

  void SetUp() override {
    StoredJob row;
    row.meta = job->meta;
    store.add(row);
  }
  v1::JobStatus::State stored_state() const { return store.jobs().at(0).state; }
  Job::Written written() {
    MutexLock lock(job->write_mu);
    return job->written;
  }
};

TEST_F(SnapshotWriterTest, ASnapshotIsWrittenAsImageAndCheckpoint) {
  merge_passes(job->plan, 1);
  ImageSnapshot snap = snapshotter.take(job, true, true, now);
  const SnapshotOutcome out = writer.write(snap);
  EXPECT_EQ(out.image, R::kWritten);
  EXPECT_EQ(out.checkpoint, R::kWritten);
  EXPECT_FALSE(out.release_film);  // live
  EXPECT_EQ(sink.writes(job->id()), 1);
  EXPECT_EQ(sink.film(job->id()).pixels()[0].r, job->plan.film().pixels()[0].r);
  EXPECT_EQ(sink.metadata(job->id()).at("job"), job->id());
  const std::optional<Checkpoint> cp = store.read_checkpoint(job->id());
  ASSERT_TRUE(cp);
  EXPECT_EQ(cp->state.merges, job->plan.merges());
  EXPECT_EQ(written().image_seq, snap.seq);
  EXPECT_EQ(written().checkpoint_merges, snap.merges);
}

TEST_F(SnapshotWriterTest, ASnapshotOlderThanWhatIsWrittenIsSkipped) {
  merge_passes(job->plan, 1);
  ImageSnapshot older = snapshotter.take(job, true, true, now);
  merge_passes(job->plan, 2);
  ImageSnapshot newer = snapshotter.take(job, true, true, now);
  ASSERT_EQ(writer.write(newer).image, R::kWritten);
  const SnapshotOutcome out = writer.write(older);  // its writer was slower
  EXPECT_EQ(out.image, R::kSkipped);
  EXPECT_EQ(out.checkpoint, R::kSkipped);
  EXPECT_EQ(sink.writes(job->id()), 1);
  EXPECT_EQ(store.read_checkpoint(job->id())->state.merges, newer.merges);
}

TEST_F(SnapshotWriterTest, ADoneJobsEndIsRecordedOnlyOnceItsWholeFilmIsInACheckpoint) {
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  ImageSnapshot image_only = snapshotter.take(job, true, false, now);
  SnapshotOutcome out = writer.write(image_only);
  EXPECT_EQ(out.image, R::kWritten);
  EXPECT_FALSE(job->end_recorded);  // a restart must find its whole film with a DONE row
  EXPECT_EQ(stored_state(), v1::JobStatus::QUEUED);
  EXPECT_TRUE(released.empty());
  EXPECT_FALSE(out.release_film);
  ImageSnapshot both = snapshotter.take(job, true, true, now);
  out = writer.write(both);
  EXPECT_TRUE(job->end_recorded);
  EXPECT_EQ(stored_state(), v1::JobStatus::DONE);
  EXPECT_EQ(released, std::vector<std::string>{job->meta.scene_hash});
  EXPECT_TRUE(out.release_film);
  ImageSnapshot again = snapshotter.take(job, true, true, now);
  writer.write(again);
  EXPECT_EQ(released.size(), 1u);  // recorded once
}

TEST_F(SnapshotWriterTest, ACancelledJobsEndIsRecordedAtOnce) {
  merge_passes(job->plan, 1);
  lifecycle.end(*job, v1::JobStatus::CANCELLED, now, fx);
  ImageSnapshot image_only = snapshotter.take(job, true, false, now);
  const SnapshotOutcome out = writer.write(image_only);
  EXPECT_TRUE(job->end_recorded);
  EXPECT_EQ(stored_state(), v1::JobStatus::CANCELLED);
  EXPECT_FALSE(out.release_film);  // no checkpoint holds the film yet
}

TEST_F(SnapshotWriterTest, AFailureIsInTheOutcomeWithTheDataFolderHidden) {
  class FullDisk : public MemoryImageSink {
   public:
    explicit FullDisk(std::string dir) : dir_(std::move(dir)) {}
    void write(const std::string& job, const Film&, const ImageMetadata&) override {
      throw std::runtime_error("cannot write " + dir_ + "/jobs/" + job + "/image.exr: No space left on device");
    }

   private:
    std::string dir_;
  } full(options.data_dir);
  const SnapshotWriter failing(full, store, {nullptr, nullptr, options.data_dir});
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  ImageSnapshot snap = snapshotter.take(job, true, true, now);
  const SnapshotOutcome out = failing.write(snap);
  EXPECT_EQ(out.image, R::kFailed);
  EXPECT_EQ(out.image_why, "cannot write <data>/jobs/" + job->id() + "/image.exr: No space left on device");
  EXPECT_EQ(out.checkpoint, R::kWritten);
  EXPECT_TRUE(job->end_recorded);  // the checkpoint holds the whole film
  EXPECT_FALSE(out.release_film);  // but the image does not: the film stays for a retry
  EXPECT_EQ(written().image_seq, 0u);
  EXPECT_FALSE(SnapshotWriter::image_current(*job, false, job->plan.merges()));
}

TEST_F(SnapshotWriterTest, AFailedDatabaseWriteLeavesTheEndToRecordAgain) {
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  ImageSnapshot snap = snapshotter.take(job, true, true, now);
  store.fail_writes = true;
  const SnapshotOutcome out = writer.write(snap);
  EXPECT_EQ(out.checkpoint, R::kFailed);
  EXPECT_EQ(out.checkpoint_why, "checkpoint: disk I/O error (a test's)");
  EXPECT_FALSE(job->end_recorded);
  EXPECT_FALSE(out.release_film);
  EXPECT_TRUE(released.empty());
}

TEST_F(SnapshotWriterTest, ALiveJobsImageIsCurrentOnceAnyIsWrittenAnEndedJobsOnlyWhole) {
  EXPECT_FALSE(SnapshotWriter::image_current(*job, true, 0));  // none yet
  v1::Image img;
  EXPECT_FALSE(writer.read_image(*job, true, 0, true, true, &img));
  merge_passes(job->plan, 1);
  ImageSnapshot snap = snapshotter.take(job, true, false, now);
  writer.write(snap);
  merge_passes(job->plan, 2);
  const uint64_t merges = job->plan.merges();
  EXPECT_TRUE(SnapshotWriter::image_current(*job, true, merges));    // a live job's latest
  EXPECT_FALSE(SnapshotWriter::image_current(*job, false, merges));  // not the whole film
  EXPECT_TRUE(writer.read_image(*job, true, merges, true, true, &img));
  EXPECT_FALSE(writer.read_image(*job, false, merges, true, true, &img));
  snap = snapshotter.take(job, true, false, now);
  writer.write(snap);
  EXPECT_TRUE(SnapshotWriter::image_current(*job, false, merges));
}

TEST(WithoutDir, TheDataFolderIsNamedDataEverywhereInAMessage) {
  EXPECT_EQ(without_dir("/d/x: cannot open /d/y", "/d"), "<data>/x: cannot open <data>/y");
  EXPECT_EQ(without_dir("/d/x", ""), "/d/x");
}

}  // namespace
}  // namespace tessera
