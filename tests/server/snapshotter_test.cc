// Snapshotter decides when a progressive image or checkpoint is due and keeps one writer
// per job (later asks are marked due, never queued); SnapshotWriter writes band by band,
// copying the film a band at a time, and records a job's end once disk holds it.
#include "server/snapshotter.h"

#include <gtest/gtest.h>

#include "server/checkpoint.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

using testing::kTiles;
using testing::merge_passes;
using testing::plausible_sums;
using R = SnapshotOutcome::Result;

class SnapshotterTest : public testing::PartsTest {
 protected:
  std::shared_ptr<Job> job = add_still();
  // What the writer would do next, then nothing: the writer stops.
  SnapshotPlan drain_one() {
    const SnapshotPlan p = snapshotter.next(*job, now);
    EXPECT_FALSE(snapshotter.next(*job, now).image);
    EXPECT_FALSE(job->snaps.writing);
    return p;
  }
};

TEST_F(SnapshotterTest, NothingIsDueRightAfterTheSubmit) {
  EXPECT_FALSE(snapshotter.after_merge(*job, now));  // no frame pass, no checkpoint interval
  EXPECT_FALSE(snapshotter.after_merge(*job, now + options.checkpoint_seconds - 0.001));
  EXPECT_FALSE(job->snaps.writing);
}

TEST_F(SnapshotterTest, AnImageNeedsANewFramePassAndItsInterval) {
  merge_passes(job->plan, 1);
  ASSERT_TRUE(snapshotter.after_merge(*job, now));  // the first frame pass: the first image is never late
  SnapshotPlan p = drain_one();
  EXPECT_TRUE(p.image);
  EXPECT_FALSE(p.checkpoint);
  EXPECT_EQ(job->snaps.image_frame_passes, 1u);
  EXPECT_EQ(job->snaps.last_image, now);
  // The same frame pass: no other image, however long after (short of a checkpoint).
  EXPECT_FALSE(snapshotter.after_merge(*job, now + options.checkpoint_seconds - 0.001));
  merge_passes(job->plan, 2);  // a new frame pass, before the image interval passed
  const double at = now + options.image_interval_seconds;
  ASSERT_EQ(options.image_interval_seconds, options.checkpoint_seconds);
  EXPECT_FALSE(snapshotter.after_merge(*job, at - 0.001));
  ASSERT_TRUE(snapshotter.after_merge(*job, at));
  p = drain_one();
  EXPECT_TRUE(p.image);
  EXPECT_TRUE(p.checkpoint);  // its interval passed too
  EXPECT_EQ(job->snaps.image_frame_passes, 2u);
}

TEST_F(SnapshotterTest, WithoutANewFramePassOnlyACheckpointIsDue) {
  merge_passes(job->plan, 1);
  ASSERT_TRUE(snapshotter.after_merge(*job, now));
  drain_one();
  ASSERT_TRUE(snapshotter.after_merge(*job, now + options.checkpoint_seconds));
  const SnapshotPlan p = drain_one();
  EXPECT_FALSE(p.image);
  EXPECT_TRUE(p.checkpoint);
  EXPECT_EQ(job->snaps.last_checkpoint, now + options.checkpoint_seconds);
}

TEST_F(SnapshotterTest, SlowWritesStretchTheIntervalsToKeepTheirShare) {
  // The last write took 1 s: images and checkpoints come every kWriteShare x 1 = 20 s, not
  // every 5 s.
  job->snaps.write_seconds = 1;
  job->snaps.last_image = now;
  merge_passes(job->plan, 1);
  const double every = Snapshotter::kWriteShare * 1;
  ASSERT_GT(every, options.checkpoint_seconds);
  EXPECT_FALSE(snapshotter.after_merge(*job, now + every - 0.001));
  ASSERT_TRUE(snapshotter.after_merge(*job, now + every));
  const SnapshotPlan p = drain_one();
  EXPECT_TRUE(p.image);
  EXPECT_TRUE(p.checkpoint);
}

// At most one writer per job: asks while it writes are marked due and taken by it before
// it stops, so a snapshot that cannot keep up merges into the next instead of queuing.
TEST_F(SnapshotterTest, OneWriterAJobLaterAsksAreTakenByIt) {
  EXPECT_TRUE(snapshotter.request(*job, true, false));  // this caller writes
  EXPECT_TRUE(job->snaps.writing);
  const SnapshotPlan first = snapshotter.next(*job, now);
  EXPECT_TRUE(first.image);
  EXPECT_FALSE(first.checkpoint);
  EXPECT_FALSE(snapshotter.request(*job, false, true));  // while it writes: marked due
  EXPECT_FALSE(snapshotter.request(*job, true, false));
  const SnapshotPlan second = snapshotter.next(*job, now);  // the writer looks again
  EXPECT_TRUE(second.image);
  EXPECT_TRUE(second.checkpoint);
  EXPECT_FALSE(snapshotter.next(*job, now).checkpoint);  // nothing more: it stops
  EXPECT_FALSE(job->snaps.writing);
  EXPECT_TRUE(snapshotter.request(*job, true, false));  // the next ask writes again
}

TEST_F(SnapshotterTest, NextDescribesTheWrite) {
  merge_passes(job->plan, 1);
  lifecycle.start(*job, now - 3, fx);
  ASSERT_TRUE(snapshotter.request(*job, true, true));
  const SnapshotPlan p = snapshotter.next(*job, now);
  EXPECT_EQ(p.merges, job->plan.merges());
  EXPECT_EQ(job->snaps.checkpoint_merges, p.merges);  // a checkpoint of this version is on its way
  EXPECT_EQ(p.elapsed, 3);
  EXPECT_FALSE(p.ended);
  EXPECT_FALSE(p.checkpoint_on_disk);
  EXPECT_EQ(p.meta.at("job"), job->id());
  EXPECT_EQ(p.meta.at("frame_passes"), "1");
  EXPECT_EQ(p.meta.count("frame"), 0u);  // a still
  EXPECT_EQ(p.meta.count("final"), 0u);  // (only an ended DONE job's image: what a restart leaves be)
  const std::shared_ptr<Job> done = add_still();
  render_all(*done, add_worker());
  ASSERT_EQ(done->state(), v1::JobStatus::DONE);  // (its final image asked for)
  EXPECT_EQ(snapshotter.next(*done, now).meta.at("final"), "1");
}

TEST_F(SnapshotterTest, AFramesImageNamesItsFrameAndTime) {
  Sequence& s = add_sequence({48});
  Job& frame = start_frame(s);
  ASSERT_TRUE(snapshotter.request(frame, true, false));
  const SnapshotPlan p = snapshotter.next(frame, now);
  EXPECT_EQ(p.meta.at("frame"), "48");
  EXPECT_EQ(p.meta.at("time"), "2");  // frame / fps
}

TEST_F(SnapshotterTest, WrittenAppliesTheOutcomeAndCountsIt) {
  ASSERT_TRUE(snapshotter.request(*job, true, true));
  SnapshotPlan p = snapshotter.next(*job, now);
  SnapshotOutcome out;
  out.image = R::kFailed;
  out.image_why = "disk full";
  out.checkpoint = R::kWritten;
  out.seconds = 0.25;
  snapshotter.written(*job, p, out, counters);
  EXPECT_EQ(job->image_error, "disk full");
  EXPECT_EQ(job->checkpoint_error, "");
  EXPECT_EQ(job->snaps.write_seconds, 0.25);
  EXPECT_EQ(job->written.checkpoints, 1u);
  EXPECT_EQ(job->written.checkpoint_merges, p.merges);
  EXPECT_EQ(job->written.images, 0u);
  EXPECT_EQ(counters.image_errors, 1u);
  EXPECT_EQ(counters.checkpoints_written, 1u);
  out = {};
  out.image = R::kWritten;
  out.seconds = 0.5;
  snapshotter.written(*job, p, out, counters);
  EXPECT_EQ(job->image_error, "");  // cleared by the next write
  EXPECT_EQ(job->snaps.write_seconds, 0.5);
  EXPECT_EQ(counters.images_written, 1u);
  EXPECT_TRUE(job->plan.has_film());  // live: the film stays
}

TEST_F(SnapshotterTest, AnEndedJobsFilmIsReleasedOnlyWhenDiskHoldsItAll) {
  lifecycle.end(*job, v1::JobStatus::CANCELLED, now, fx);
  ASSERT_TRUE(snapshotter.final_snapshot(*job, now));
  const SnapshotPlan p = snapshotter.next(*job, now);
  ASSERT_TRUE(p.ended);
  SnapshotOutcome out;
  out.image = R::kWritten;  // the image, not yet a checkpoint
  snapshotter.written(*job, p, out, counters);
  EXPECT_TRUE(job->plan.has_film());
  job->end_recorded = true;
  out.checkpoint = R::kWritten;
  snapshotter.written(*job, p, out, counters);
  EXPECT_FALSE(job->plan.has_film());
  EXPECT_FALSE(snapshotter.next(*job, now).image);  // nothing left to write: the writer stops
  ASSERT_TRUE(snapshotter.request(*job, true, true));
  EXPECT_FALSE(snapshotter.next(*job, now).image);
}

// ---- SnapshotWriter, over MemoryImageSink and MemoryJobStore ----

class SnapshotWriterTest : public SnapshotterTest {
 protected:
  MemoryImageSink sink;
  MemoryJobStore store;
  std::vector<std::string> released;  // scenes whose use ended
  SnapshotWriter writer{
      sink, store, {[this](const std::string& h) { released.push_back(h); }, nullptr, options.data_dir}};
  int bands_copied = 0;

  void SetUp() override {
    StoredJob row;
    row.meta = job->meta;
    store.add(row);
  }
  // As the coordinator copies a band: under its lock, from the live plan.
  std::function<bool(uint32_t, BandCopy*)> copier(Job& j) {
    return [this, &j](uint32_t band, BandCopy* out) {
      if (!j.plan.has_film()) return false;
      j.plan.copy_band(band, out);
      ++bands_copied;
      return true;
    };
  }
  // One write of what is asked, applied as the coordinator applies it.
  SnapshotOutcome write(bool image, bool checkpoint, SnapshotWriter* w = nullptr) {
    snapshotter.request(*job, image, checkpoint);
    const SnapshotPlan p = snapshotter.next(*job, now);
    const SnapshotOutcome out = (w ? *w : writer).write(*job, p, copier(*job));
    snapshotter.written(*job, p, out, counters);
    EXPECT_FALSE(snapshotter.next(*job, now).image);  // the writer stops
    return out;
  }
  v1::JobStatus::State stored_state() const { return store.jobs().at(0).state; }
};

TEST_F(SnapshotWriterTest, ASnapshotIsWrittenBandByBandAsImageAndCheckpoint) {
  merge_passes(job->plan, 1);
  const SnapshotOutcome out = write(true, true);
  EXPECT_EQ(out.image, R::kWritten);
  EXPECT_EQ(out.checkpoint, R::kWritten);
  EXPECT_EQ(bands_copied, int(job->plan.bands()));  // each band copied once, for both
  EXPECT_EQ(sink.writes(job->id()), 1);
  const Film image = sink.film(job->id());
  ASSERT_EQ(image.pixels().size(), job->plan.film().pixels().size());
  for (size_t i = 0; i < image.pixels().size(); ++i) ASSERT_EQ(image.pixels()[i].r, job->plan.film().pixels()[i].r);
  EXPECT_EQ(sink.metadata(job->id()).at("job"), job->id());
  FramePlan restored(job->plan.settings());
  ASSERT_TRUE(store.read_checkpoint(job->id(), restored));
  EXPECT_EQ(restored.samples_merged(), job->plan.samples_merged());
  EXPECT_EQ(job->written.images, 1u);
  EXPECT_EQ(job->written.checkpoint_merges, job->plan.merges());
  EXPECT_FALSE(job->end_recorded);  // live
}

TEST_F(SnapshotWriterTest, AFilmGoneMidWriteWritesNothing) {
  merge_passes(job->plan, 1);
  snapshotter.request(*job, true, true);
  const SnapshotPlan p = snapshotter.next(*job, now);
  int calls = 0;
  const SnapshotOutcome out = writer.write(*job, p, [&](uint32_t band, BandCopy* copy) {
    if (++calls > 1) return false;  // released after the first band
    job->plan.copy_band(band, copy);
    return true;
  });
  EXPECT_EQ(out.image, R::kSkipped);
  EXPECT_EQ(out.checkpoint, R::kSkipped);
  EXPECT_EQ(sink.writes(job->id()), 0);  // nothing half-written put in place
  EXPECT_FALSE(store.checkpoint_bytes(job->id()));
}

TEST_F(SnapshotWriterTest, ADoneJobsEndIsRecordedOnlyOnceItsWholeFilmIsInACheckpoint) {
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  SnapshotOutcome out = write(true, false);
  EXPECT_EQ(out.image, R::kWritten);
  EXPECT_FALSE(job->end_recorded);  // a restart must find its whole film with a DONE row
  EXPECT_EQ(stored_state(), v1::JobStatus::QUEUED);
  EXPECT_TRUE(released.empty());
  EXPECT_TRUE(job->plan.has_film());
  out = write(true, true);
  EXPECT_TRUE(out.end_recorded);
  EXPECT_TRUE(job->end_recorded);
  EXPECT_EQ(stored_state(), v1::JobStatus::DONE);
  EXPECT_EQ(released, std::vector<std::string>{job->meta.scene_hash});
  EXPECT_FALSE(job->plan.has_film());            // disk holds it all
  EXPECT_FALSE(write(true, true).end_recorded);  // recorded once (nothing left to write)
  EXPECT_EQ(released.size(), 1u);
}

TEST_F(SnapshotWriterTest, AnEndIsRecordedWithACheckpointOfTheFinalFilmWrittenBefore) {
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  write(false, true);  // the final film's checkpoint; the end then recorded with it
  EXPECT_TRUE(job->end_recorded);
}

TEST_F(SnapshotWriterTest, ACancelledJobsEndIsRecordedAtOnce) {
  merge_passes(job->plan, 1);
  lifecycle.end(*job, v1::JobStatus::CANCELLED, now, fx);
  write(true, false);
  EXPECT_TRUE(job->end_recorded);
  EXPECT_EQ(stored_state(), v1::JobStatus::CANCELLED);
  EXPECT_TRUE(job->plan.has_film());  // no checkpoint holds the film yet
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
  SnapshotWriter failing(full, store, {nullptr, nullptr, options.data_dir});
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  const SnapshotOutcome out = write(true, true, &failing);
  EXPECT_EQ(out.image, R::kFailed);
  EXPECT_EQ(out.image_why, "cannot write <data>/jobs/" + job->id() + "/image.exr: No space left on device");
  EXPECT_EQ(out.checkpoint, R::kWritten);
  EXPECT_TRUE(job->end_recorded);     // the checkpoint holds the whole film
  EXPECT_TRUE(job->plan.has_film());  // but the image does not: the film stays for a retry
  EXPECT_EQ(job->written.images, 0u);
  EXPECT_FALSE(Snapshotter::image_current(*job, false, job->plan.merges()));
}

TEST_F(SnapshotWriterTest, AFailedCheckpointLeavesTheEndToRecordAgain) {
  merge_passes(job->plan, testing::kPasses);
  lifecycle.end(*job, v1::JobStatus::DONE, now, fx);
  store.fail_writes = true;
  const SnapshotOutcome out = write(true, true);
  EXPECT_EQ(out.checkpoint, R::kFailed);
  EXPECT_EQ(out.checkpoint_why, "checkpoint: disk I/O error (a test's)");
  EXPECT_FALSE(job->end_recorded);
  EXPECT_TRUE(job->plan.has_film());
  EXPECT_TRUE(released.empty());
}

TEST_F(SnapshotWriterTest, ALiveJobsImageIsCurrentOnceAnyIsWrittenAnEndedJobsOnlyWhole) {
  EXPECT_FALSE(Snapshotter::image_current(*job, true, 0));  // none yet
  merge_passes(job->plan, 1);
  write(true, false);
  merge_passes(job->plan, 2);
  const uint64_t merges = job->plan.merges();
  EXPECT_TRUE(Snapshotter::image_current(*job, true, merges));    // a live job's latest
  EXPECT_FALSE(Snapshotter::image_current(*job, false, merges));  // not the whole film
  write(true, false);
  EXPECT_TRUE(Snapshotter::image_current(*job, false, merges));
}

// ---- splats (frame_splats.h) ----

// A made-up record for (tile, pass): its own pixel, and one every record shares.
SplatRecord splat_record(uint32_t tile, uint32_t pass) {
  SplatRecord r;
  r.paths = 10 + tile;
  r.entries.push_back({5, {1, 1, 1, 1}});
  r.entries.push_back({uint32_t(100 + tile * 7 + pass * 3), {int64_t(tile) + 1, int64_t(pass) + 1, 3, 4}});
  return r;
}
void merge_with_splats(Job& j, uint32_t tile, uint32_t pass) {
  ASSERT_EQ(j.plan.merge(tile, pass, plausible_sums(j.plan, tile, pass)), FramePlan::Merge::kMerged);
  j.splats.add(tile, pass, {splat_record(tile, pass)});
}
std::vector<SplatSums> all_splats(const FrameSplats& s, const Rect& w) {
  std::vector<SplatSums> out;
  if (s.film()) s.film()->copy_rows(0, w.h, false, &out);
  return out;
}
bool same(const std::vector<SplatSums>& a, const std::vector<SplatSums>& b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](const SplatSums& x, const SplatSums& y) {
           return std::equal(x.rgb, x.rgb + 3, y.rgb) && x.lum2 == y.lum2;
         });
}

// The checkpoint's splats are frozen after its bands: a tile merged after its band was
// copied has its splats in the checkpoint past its film's progress (its frontier), and
// those merged while the splats are written wait for the thaw. Restored, the tile's passes
// rendered again bring records the frontier holds already: not added twice, so the frame's
// splats end as if the coordinator had never stopped.
TEST_F(SnapshotWriterTest, ACheckpointsSplatsAreNeverBehindItsBandsAndRestoreWithoutDoubles) {
  for (uint32_t t = 0; t < kTiles; ++t) merge_with_splats(*job, t, 0);
  snapshotter.request(*job, true, true);
  const SnapshotPlan p = snapshotter.next(*job, now);
  int steps = 0;
  const SnapshotOutcome out = writer.write(
      *job, p,
      [&](uint32_t band, BandCopy* copy) {
        job->plan.copy_band(band, copy);
        job->splats.copy_band(copy);
        if (band == 0) merge_with_splats(*job, 0, 1);  // after its band was copied
        return true;
      },
      [&](const std::function<void()>& step) {
        step();
        if (++steps == 2) {  // frozen, the first splat band copied: tile 1's pass 1 waits
          ASSERT_TRUE(job->splats.frozen());
          merge_with_splats(*job, 1, 1);
        }
      });
  EXPECT_EQ(out.checkpoint, R::kWritten);
  EXPECT_FALSE(job->splats.frozen());  // thawed, the waiting record added
  const Rect w = job->plan.settings().effective_window();
  // The image holds the splats folded in (the bands' scale: 9 paths' worth each pixel).
  const Film image = sink.film(job->id());
  EXPECT_NE(image.at(5, 0).r, job->plan.film().at(5, 0).r);

  Job restored(job->meta, job->plan.settings());
  ASSERT_TRUE(store.read_checkpoint(job->id(), restored.plan, true, &restored.splats));
  EXPECT_EQ(restored.plan.progress(0).passes_done, 1u);  // band 0 was copied before its pass 1
  EXPECT_EQ(restored.splats.frontier(0), 2u);            // its splats were not
  EXPECT_EQ(restored.splats.frontier(1), 1u);            // frozen before tile 1's pass 1
  merge_with_splats(restored, 0, 1);                     // rendered again: its splats are in already
  merge_with_splats(restored, 1, 1);
  EXPECT_TRUE(same(all_splats(restored.splats, w), all_splats(job->splats, w)));
  EXPECT_EQ(restored.splats.film()->paths(), job->splats.film()->paths());
  EXPECT_EQ(job->splats.film()->paths(), 9u * 10 + 36 + 10 + 11);
}

// Results taken back from the film during a write (a liar found: Job::resets) make its
// checkpoint one not to keep: it fails, and is written again.
TEST_F(SnapshotWriterTest, ACheckpointWrittenAcrossAResetIsNotKept) {
  for (uint32_t t = 0; t < kTiles; ++t) merge_with_splats(*job, t, 0);
  snapshotter.request(*job, false, true);
  const SnapshotPlan p = snapshotter.next(*job, now);
  const SnapshotOutcome out = writer.write(*job, p, copier(*job), [&](const std::function<void()>& step) {
    ++job->resets;
    step();
  });
  EXPECT_EQ(out.checkpoint, R::kFailed);
  EXPECT_NE(out.checkpoint_why.find("taken back"), std::string::npos) << out.checkpoint_why;
  EXPECT_FALSE(job->splats.frozen());
}

TEST(WithoutDir, TheDataFolderIsNamedDataEverywhereInAMessage) {
  EXPECT_EQ(without_dir("/d/x: cannot open /d/y", "/d"), "<data>/x: cannot open <data>/y");
  EXPECT_EQ(without_dir("/d/x", ""), "/d/x");
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a farm EXR with AOV layers did not say which (tessera render's has
// tessera/aovs; tessera denoise and tools read it). Now it does, the same text.
TEST_F(SnapshotterTest, AnImageWithAovLayersNamesThem) {
  RenderSettings s = testing::small_settings();
  s.aovs = kAovAlbedo | kAovNormal;
  const std::shared_ptr<Job> job = add_still(s);
  ASSERT_TRUE(snapshotter.request(*job, true, false));
  EXPECT_EQ(snapshotter.next(*job, now).meta.at("aovs"), aov_names(s.aovs));
  const std::shared_ptr<Job> plain = add_still();
  ASSERT_TRUE(snapshotter.request(*plain, true, false));
  EXPECT_EQ(snapshotter.next(*plain, now).meta.count("aovs"), 0u);
}

}  // namespace
}  // namespace tessera
