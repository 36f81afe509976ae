// Scenes arriving in pieces (UploadScene): each written straight to disk as it comes, into a
// staging folder of its own beside the SceneStore's scenes (under the data folder), and
// checked as it comes (proto/scene_chunks.h: paths, sizes, order, then the content hash):
// never held in memory.
// A finished upload waits there, at most `kept_seconds`, for the SubmitJob that names it by
// its id (unguessable, good for its uploader only, once); that submit has the SceneStore
// check the scene with the job's settings and keep it. An upload cut short or refused
// leaves nothing behind, and staging folders are removed at start
// (SceneStore::remove_unused). Uploads count against their owner's scene bytes
// (--max-scene-bytes-per-client) from their first message on: a client cannot fill the
// disk with them.
//
// Thread-safe. Its lock is a leaf, held for bookkeeping only: never across the disk, the
// network or another lock.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "server/clock.h"
#include "server/scene_store.h"

namespace tessera {

class SceneUploads {
 public:
  SceneUploads(SceneStore& scenes, const Clock& clock, double kept_seconds)
      : scenes_(scenes), clock_(clock), kept_seconds_(kept_seconds) {}

  // Takes one upload: `next` gives each message of the stream in turn, false at its end.
  // `owner_bytes`: the owner's scene bytes in live jobs; with its uploads here and this
  // one, at most `limit`. Throws RequestError: kInvalidArgument (a bad manifest or piece, a
  // stream that stops early, bytes that do not hash to the manifest's hash),
  // kResourceExhausted (the limit; the disk), naming the problem.
  v1::SceneUpload receive(const std::string& owner, const std::function<bool(v1::SceneChunk*)>& next,
                          uint64_t owner_bytes, uint64_t limit);
  // What `owner`'s finished upload `id` weighs (bundle_bytes), for admission. Throws
  // RequestError (kNotFound) when there is none.
  uint64_t bytes(const std::string& id, const std::string& owner);
  // Hands `owner`'s finished upload `id` to the SceneStore (SceneStore::keep: checked with
  // `check`, kept, one use) whatever comes of it, and returns its content hash; sets
  // `main_file`. Throws RequestError (kNotFound), or what keep() throws.
  std::string submit(const std::string& id, const std::string& owner, const SceneStore::Check& check,
                     std::string* main_file);
  // Bytes of `owner`'s uploads here, in flight and finished.
  uint64_t held(const std::string& owner);
  // Takes finished uploads past their time out of the table and off the disk (each upload
  // and submit does, and the coordinator's reaper once a minute: an upload nobody submits
  // left its folder until the next upload or submit, for good if none came).
  void drop_expired();

 private:
  struct Upload {
    std::string owner;
    std::string folder;  // a SceneStore::staging_folder
    v1::SceneManifest manifest;
    uint64_t bytes = 0;
    double expires = -1;  // < 0: still arriving
  };
  void forget(const std::string& id);  // and its folder
  uint64_t held_locked(const std::string& owner) const;

  SceneStore& scenes_;
  const Clock& clock_;
  const double kept_seconds_;
  std::mutex mu_;
  std::map<std::string, Upload> uploads_;  // by id
};

}  // namespace tessera
