// A submitted job made ready outside the coordinator's lock, once Admission has let it in:
// its scene checked (loaded exactly as a worker will load it, against its settings), its
// films made (for a large frame, allocating and zeroing one would stall every worker if
// done under the lock) and its row recorded durably, before the client hears of it.
#pragma once

#include <memory>
#include <string>

#include "server/admission.h"
#include "server/job_store.h"
#include "server/scene_store.h"
#include "server/scene_uploads.h"

namespace tessera {

struct Submission {
  std::shared_ptr<Job> job;            // a still
  std::shared_ptr<Sequence> sequence;  // or a sequence, its first frame's job prepared
};

// `meta` has its id, owner and submission order; the rest comes from the request, whose
// scene is its files or the finished upload it names (in `uploads`). Throws RequestError:
// the scene refused (kInvalidArgument, the loader's message), no such upload (kNotFound),
// or the row not recorded (kResourceExhausted; the scene's use is released). `data_dir` is
// hidden from messages.
Submission prepare_submission(const v1::SubmitJobRequest& req, const Admission& a, JobMeta meta, SceneStore& scenes,
                              JobStore& store, const std::string& data_dir, SceneUploads* uploads = nullptr);

}  // namespace tessera
