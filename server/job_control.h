// Changing a job after its submit: its priority, a requeue of a FAILED or CANCELLED job
// (a sequence: its frames that are not DONE), and a delete. Each goes in steps: the checks
// and the state changes run here, under the coordinator's lock; the disk work runs outside
// it (load_requeue, finish_removal below), between them. The record on disk is each
// operation's commit point, so a crash in the middle leaves either the old job or the new
// state, never half of one:
//   requeue  the row says QUEUED again (JobStore::requeue) before anything in memory
//            changes: a restart then takes the job up from its checkpoints, as this run does.
//   delete   the row goes (JobStore::remove) before any file: a restart removes the files
//            of jobs it has no row for (ImageSink::remove_unknown, SceneStore::remove_unused).
// Only the job's owner may change it, or an admin (`any`).
#pragma once

#include <memory>
#include <set>
#include <string>
#include <vector>

#include "server/admission.h"
#include "server/effects.h"
#include "server/job_lifecycle.h"
#include "server/scene_store.h"
#include "server/snapshotter.h"

namespace tessera {

class JobControl {
 public:
  JobControl(JobTable& jobs, JobLifecycle& lifecycle, const Snapshotter& snapshots, CoordinatorCounters& counters)
      : jobs_(jobs), lifecycle_(lifecycle), snapshots_(snapshots), counters_(counters) {}

  // The job's (or sequence's and its frames') priority, once its row has it.
  void set_priority(const std::string& id, int32_t priority, Effects& fx);

  // A delete in progress.
  struct Removal {
    std::string id, scene_hash;
    std::vector<std::shared_ptr<Job>> jobs;  // the still, or the sequence's started frames
    std::shared_ptr<Sequence> sequence;
    std::vector<std::string> job_ids;  // whose files go: the still, or every frame of the sequence
  };
  // Marks the job (and its frames) removed, so that no image or checkpoint of it is begun
  // again, and ends it CANCELLED if it is live. Throws RequestError.
  Removal begin_delete(const std::string& id, const std::string& requester, bool any, double now, Effects& fx);
  // Whether its writers have stopped and a sequence's end is not being recorded.
  static bool quiet(const Removal& r);
  // Once quiet: whether it still holds a use of its scene (its end was never recorded).
  static bool holds_scene(const Removal& r);
  // Its row is gone: it leaves memory.
  void removed(const Removal& r, Effects& fx);
  // Its row could not be removed: it stays, ended, and its end is recorded as usual.
  void delete_failed(const Removal& r, double now, Effects& fx);
  // An archived job's delete (archive.h): only its files, from its row.
  static Removal archived_removal(const StoredJob& row);
  // An archived job being deleted or brought back for a requeue: one request at a time (a
  // second, and a delete or requeue of it in memory meanwhile, are refused as busy).
  void begin_archived(const std::string& id);
  void end_archived(const std::string& id) { archived_changing_.erase(id); }

  // A requeue in progress.
  struct Requeue {
    std::string id, scene_hash;
    std::shared_ptr<Sequence> sequence;
    std::vector<std::shared_ptr<Job>> ended;  // the jobs to take up again
    std::vector<std::shared_ptr<Job>> fresh;  // the same, their plans read back (load_requeue)
    std::vector<double> elapsed;              // each one's render seconds so far
    std::vector<bool> checkpointed;
    uint64_t scene_bytes = 0;
  };
  // Refuses what cannot be requeued (live, DONE, its end not yet on disk, a frame, being
  // changed) and marks it being changed. Throws RequestError.
  Requeue begin_requeue(const std::string& id, const std::string& requester, bool any);
  // What the requeue asks of the limits a submit passes (admission.h), and whose they are
  // (the owner's, whoever asks): a frame's pixels, the samples its unfinished frames or
  // its plan still need, its scene.
  static Admission requeue_admission(const Requeue& q, std::string* owner);
  // Throws RequestError (kFailedPrecondition) for a job in `state` that cannot be requeued
  // (`durable`: its end is on disk).
  static void refuse_requeue(const std::string& id, v1::JobStatus::State state, bool durable);
  // Whether the jobs' writers have stopped.
  static bool quiet(const Requeue& q) { return none_writing(q.ended); }
  void requeue_failed(const Requeue& q);
  // The fresh jobs take the ended ones' places, live again.
  void finish_requeue(Requeue& q, double now, Effects& fx);

 private:
  JobTable& jobs_;
  JobLifecycle& lifecycle_;
  const Snapshotter& snapshots_;
  CoordinatorCounters& counters_;
  std::set<std::string> archived_changing_;
};

// ---- the disk work, without the coordinator's lock ----

// Pins and checks the scene, makes the row live again (the commit point), then reads each
// job's plan back from its checkpoint (a damaged or missing one: that job starts over).
// Throws RequestError, having changed nothing, when the scene or the row cannot be had.
void load_requeue(JobControl::Requeue& q, JobStore& store, SceneStore& scenes, const std::string& data_dir);
// Removes the row (the commit point; throws RequestError having removed nothing), then the
// files and, if no other job names it, the scene. Returns the bytes freed.
uint64_t finish_removal(const JobControl::Removal& r, bool holds_scene, JobStore& store, ImageSink& sink,
                        SceneStore& scenes, const std::string& data_dir);

}  // namespace tessera
