// Which frame of a sequence starts next. Frames start in order, when the Dispatcher finds a
// worker with room and the started frames have no ready task, at most kMaxLiveFrames at
// once (each holds a film). A frame's job (its films, slow to allocate) is made ahead
// of time outside the coordinator's lock: to_prepare() names it, make_frame() makes it
// without the lock, offer() hands it over. Runs under the coordinator's lock but for
// make_frame().
#pragma once

#include <memory>
#include <utility>
#include <vector>

#include "server/job_lifecycle.h"

namespace tessera {

class SequenceScheduler {
 public:
  static constexpr uint32_t kMaxLiveFrames = 64;

  SequenceScheduler(JobTable& jobs, JobLifecycle& lifecycle) : jobs_(jobs), lifecycle_(lifecycle) {}

  // Frame `index`'s job, with its films: reads only the sequence's constant fields, so it
  // needs no lock.
  static std::shared_ptr<Job> make_frame(const Sequence& s, size_t index);
  // True while a frame may start: some have not, and fewer than kMaxLiveFrames are live.
  static bool may_start(const Sequence& s) {
    return s.live() && s.next < s.frames.size() && s.live_frames < kMaxLiveFrames;
  }
  // Starts the next frame (its prepared job if there is one, else made here); null when
  // every frame has started.
  Job* start_next(Sequence& s, double now, Effects& fx);
  // The first frame from `next` on that has not started (after a restart, frames past
  // `next` may have); frames.size() when every one has.
  static size_t next_unstarted(const Sequence& s);
  // Sequences whose next frame has no job made yet, and that frame's index: those with no
  // live frame (the one each sequence may always start), and others while the films in
  // memory, prepared ones included (JobTable::load), stay within `max_live_pixels`.
  std::vector<std::pair<std::shared_ptr<Sequence>, size_t>> to_prepare(int64_t max_live_pixels) const;
  // A job made by make_frame() for frame `index`: kept unless the sequence moved on.
  void offer(Sequence& s, size_t index, std::shared_ptr<Job> job);

 private:
  JobTable& jobs_;
  JobLifecycle& lifecycle_;
};

}  // namespace tessera
