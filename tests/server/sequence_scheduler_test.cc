// SequenceScheduler: a sequence's frames start in order, at most kMaxLiveFrames at once,
// from a job made ahead of time outside the lock when there is one.
#include "server/sequence_scheduler.h"

#include <gtest/gtest.h>

#include <limits>

#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

constexpr int64_t kNoLimit = std::numeric_limits<int64_t>::max();

bool prepares(const std::vector<std::pair<std::shared_ptr<Sequence>, size_t>>& todo, const Sequence& s, size_t i) {
  for (const auto& [sequence, index] : todo)
    if (sequence.get() == &s && index == i) return true;
  return false;
}

class SequenceSchedulerTest : public testing::PartsTest {};

TEST_F(SequenceSchedulerTest, AFramesJobIsTheSequencesSettingsAtThatFrame) {
  const Sequence& s = add_sequence({5, 7, 9});
  const std::shared_ptr<Job> job = SequenceScheduler::make_frame(s, 1);
  EXPECT_EQ(job->id(), s.id() + "-f7");
  EXPECT_EQ(job->sequence, s.id());
  EXPECT_EQ(job->frame_index, 1u);
  EXPECT_EQ(job->plan.settings().frame, 7);
  EXPECT_EQ(from_proto(job->meta.settings).frame, 7);  // what workers are sent
  EXPECT_EQ(job->meta.owner, s.meta.owner);
  EXPECT_EQ(job->meta.seq, s.meta.seq);
  EXPECT_EQ(job->plan.film().window(), s.settings.effective_window());  // its film made here, outside the lock
}

TEST_F(SequenceSchedulerTest, FramesStartInOrderAndTheFirstStartsTheSequence) {
  Sequence& s = add_sequence({5, 7, 9});
  for (int frame : {5, 7, 9}) {
    Job* job = sequences.start_next(s, now, fx);
    ASSERT_NE(job, nullptr);
    EXPECT_EQ(job->plan.settings().frame, frame);
    EXPECT_EQ(jobs.find_job(job->id()), job);
    EXPECT_EQ(job->submitted, now);
  }
  EXPECT_EQ(s.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(s.started, now);
  EXPECT_EQ(s.next, 3u);
  EXPECT_EQ(s.frames_started, 3u);
  EXPECT_EQ(s.live_frames, 3u);
  EXPECT_EQ(sequences.start_next(s, now, fx), nullptr);  // every frame has started
}

TEST_F(SequenceSchedulerTest, ThePreparedJobIsUsedWhenItIsTheNextFrames) {
  Sequence& s = add_sequence({5, 7, 9});
  s.prepared = SequenceScheduler::make_frame(s, 0);
  Job* const prepared = s.prepared.get();
  EXPECT_EQ(sequences.start_next(s, now, fx), prepared);
  EXPECT_EQ(s.prepared, nullptr);
  s.prepared = SequenceScheduler::make_frame(s, 2);  // not the next frame's: made afresh
  Job* seven = sequences.start_next(s, now, fx);
  ASSERT_NE(seven, nullptr);
  EXPECT_NE(seven, s.prepared.get());
  EXPECT_EQ(seven->plan.settings().frame, 7);
}

TEST_F(SequenceSchedulerTest, FramesAlreadyStartedAreSkipped) {
  // After a restart, later frames may have started (their checkpoints were found).
  Sequence& s = add_sequence({5, 7, 9});
  restore_frames(s, {1});
  EXPECT_EQ(sequences.start_next(s, now, fx)->plan.settings().frame, 5);
  EXPECT_EQ(sequences.start_next(s, now, fx)->plan.settings().frame, 9);
  EXPECT_EQ(s.frames_started, 3u);
  EXPECT_EQ(sequences.start_next(s, now, fx), nullptr);
}

// BUG (server/sequence_scheduler.cc, to_prepare): after a restart leaves a gap (frames 0
// and 2 started, 1 not), starting frame 1 moves `next` onto frame 2, which has started.
// to_prepare() then names frame 2, so every reaper tick (200 ms) makes its two films
// outside the lock (231 ms for a fresh 1920x1080 film, job.h) only for offer() to drop
// them, until the Dispatcher starts another frame. It should name frame 3.
TEST_F(SequenceSchedulerTest, ToPrepareNeverNamesAFrameAlreadyStarted) {
  Sequence& s = add_sequence({0, 1, 2, 3});
  restore_frames(s, {0, 2});
  start_frame(s);  // frame 1
  const auto todo = sequences.to_prepare(kNoLimit);
  for (const auto& [sequence, index] : todo) EXPECT_FALSE(sequence->jobs[index]) << "frame " << index << " has started";
  EXPECT_TRUE(prepares(todo, s, 3));
}

TEST_F(SequenceSchedulerTest, AnEndedSequenceStartsNoFrame) {
  Sequence& s = add_sequence({5, 7});
  lifecycle.cancel(s.id(), "", true, now, fx);
  EXPECT_EQ(sequences.start_next(s, now, fx), nullptr);
  EXPECT_EQ(s.frames_started, 0u);
}

TEST_F(SequenceSchedulerTest, ToPrepareNamesLiveSequencesNextFramesWithNoJobMade) {
  Sequence& waiting = add_sequence({1, 2});
  Sequence& prepared = add_sequence({1, 2});
  prepared.prepared = SequenceScheduler::make_frame(prepared, 0);
  Sequence& all_started = add_sequence({1});
  start_frame(all_started);
  Sequence& ended = add_sequence({1, 2});
  lifecycle.cancel(ended.id(), "", true, now, fx);
  Sequence& second = add_sequence({1, 2});
  start_frame(second);
  const auto todo = sequences.to_prepare(kNoLimit);
  EXPECT_EQ(todo.size(), 2u);
  EXPECT_TRUE(prepares(todo, waiting, 0));
  EXPECT_TRUE(prepares(todo, second, 1));
}

// Frames made ahead hold films: one is made for a sequence with a live frame only while
// every film in memory, prepared ones included, stays within the limit; a sequence with
// no live frame always gets its next one (the frame it may always start).
TEST_F(SequenceSchedulerTest, ToPrepareKeepsTheFilmsInMemoryWithinTheLimit) {
  Sequence& idle = add_sequence({1, 2});
  Sequence& busy = add_sequence({1, 2});
  start_frame(busy);
  const int64_t frame = live_pixels_of(busy.settings);
  const int64_t live = jobs.load().live_pixels;  // busy's live frame
  EXPECT_EQ(live, frame);
  auto todo = sequences.to_prepare(live + frame - 1);  // no room for busy's next frame
  EXPECT_EQ(todo.size(), 1u);
  EXPECT_TRUE(prepares(todo, idle, 0));
  todo = sequences.to_prepare(live + frame);
  EXPECT_EQ(todo.size(), 2u);
  EXPECT_TRUE(prepares(todo, busy, 1));
  // A prepared frame counts as live pixels.
  idle.prepared = SequenceScheduler::make_frame(idle, 0);
  EXPECT_EQ(jobs.load().live_pixels, live + frame);
}

TEST_F(SequenceSchedulerTest, AnOfferIsKeptOnlyForTheNextFrameOfALiveSequence) {
  Sequence& s = add_sequence({5, 7, 9});
  std::shared_ptr<Job> zero = SequenceScheduler::make_frame(s, 0);
  sequences.offer(s, 0, zero);
  EXPECT_EQ(s.prepared, zero);
  sequences.offer(s, 0, SequenceScheduler::make_frame(s, 0));  // one is enough
  EXPECT_EQ(s.prepared, zero);
  start_frame(s);
  // Made for frame 0, but offered after frame 0 started without it: the sequence moved past it.
  sequences.offer(s, 0, SequenceScheduler::make_frame(s, 0));
  EXPECT_EQ(s.prepared, nullptr);
  sequences.offer(s, 1, SequenceScheduler::make_frame(s, 1));
  EXPECT_NE(s.prepared, nullptr);
  Sequence& ended = add_sequence({1, 2});
  lifecycle.cancel(ended.id(), "", true, now, fx);
  sequences.offer(ended, 0, SequenceScheduler::make_frame(ended, 0));
  EXPECT_EQ(ended.prepared, nullptr);
}

TEST_F(SequenceSchedulerTest, AtMostMaxLiveFramesAreLiveAtOnce) {
  Sequence& s = add_sequence({1, 2, 3});
  EXPECT_TRUE(SequenceScheduler::may_start(s));
  s.live_frames = SequenceScheduler::kMaxLiveFrames - 1;
  EXPECT_TRUE(SequenceScheduler::may_start(s));
  s.live_frames = SequenceScheduler::kMaxLiveFrames;
  EXPECT_FALSE(SequenceScheduler::may_start(s));
  s.live_frames = 0;
  s.next = 3;  // every frame started
  EXPECT_FALSE(SequenceScheduler::may_start(s));
  s.next = 0;
  lifecycle.cancel(s.id(), "", true, now, fx);
  EXPECT_FALSE(SequenceScheduler::may_start(s));
}

}  // namespace
}  // namespace tessera
