// Scenes by content hash, on disk: <dir>/<hash>/manifest (its SceneManifest) and
// <dir>/<hash>/files/ (the bundle's files), checked (loaded as a worker will) when added and
// kept while a live job uses them. In memory, only each live scene's manifest and uses: no
// scene bytes, whatever their size. Unpacked rather than kept as one bundle file: a scene is
// loaded where it lies (at submit, by the referee, after a restart) with no copy unpacked
// first, and the pieces workers fetch are read straight from its files.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>

#include "core/scene/scene.h"
#include "scene_bundle.h"
#include "scene_chunks.h"
#include "server/scene_loads.h"

namespace tessera {

// What a bundle's files weigh against its owner's limit (SceneWeight: paths, and sizes and
// folders in disk blocks).
uint64_t bundle_bytes(const SceneFiles& files);

class SceneStore {
 public:
  // `check`, when given, is called with the loaded scene (a job's settings against it, say)
  // and may throw to refuse it.
  using Check = std::function<void(const Scene&)>;

  // At most `loads_at_once` scenes are loaded at once (SceneLoads).
  explicit SceneStore(std::string dir, size_t loads_at_once = 2);
  // f() in turn with every scene load here (SceneLoads): a load and whatever holds the
  // scene after it (a check of its settings, a render) count as one, so that the bound
  // holds the scenes in memory, not only their loading.
  template <class F>
  auto in_turn(F&& f) const {
    return loads_.in_turn(std::forward<F>(f));
  }

  // A folder for a scene arriving, <dir>/<name>.staging-<n> (not made): its files go in
  // <folder>/files, then keep() takes it. Beside the scenes, so that a checked scene is
  // renamed into place; remove_unused() removes what a crash left.
  std::string staging_folder(const std::string& name) const;
  // A scene sent whole (SubmitJobRequest.files): written to a staging folder, then keep().
  std::string add(const std::string& main_file, const SceneFiles& files, const Check& check = nullptr);
  // The scene whose files are in <staged>/files (a staging_folder(), its bytes already
  // hashed to m.scene_hash()): loaded as a worker will, so a bad scene is refused here and
  // never reaches a worker, then renamed into place. When the same bytes are kept already,
  // those are loaded and checked instead (`check` is a job's settings: each job's own).
  // Returns the content hash; the caller holds one use of the scene until it
  // calls release(). Throws SceneError naming the main file as the user knows it (not by its
  // path here), what `check` throws, or std::runtime_error (the disk). `staged` is gone
  // afterwards whatever happened. Thread-safe, as is everything here.
  std::string keep(const std::string& staged, const v1::SceneManifest& m, const Check& check = nullptr);
  // keep() for a scene kept on disk by an earlier run (or, before protocol 5, as
  // <hash>.bundle); returns what it weighs (bundle_bytes). Throws std::runtime_error (or
  // what keep() throws) when it is missing or its bytes no longer have this hash.
  uint64_t restore(const std::string& hash);
  // Removes from the folder everything no kept scene needs and `referenced` does not name
  // (scenes of ended jobs, kept for requeue until the job is deleted), staging folders
  // (after restore()s, before any upload).
  void remove_unused(const std::set<std::string>& referenced);
  // Removes the scene from disk unless a live job uses it (a deleted job's, which no other
  // job names). Returns the bytes freed.
  uint64_t remove_if_unused(const std::string& hash);

  // Throw std::out_of_range for a hash not kept.
  v1::SceneManifest manifest(const std::string& hash) const;
  std::string main_path(const std::string& hash) const;  // the main file on disk, to load
  // Calls `write` with the scene's manifest, then with its pieces from the request's (file,
  // offset) on, each at most `chunk_bytes`, read from disk one at a time; false as soon as
  // `write` is. Throws std::out_of_range (not kept), WireError (a start past its end) or
  // std::runtime_error (its files unreadable: released meanwhile, say).
  bool send(const v1::FetchSceneRequest& req, size_t chunk_bytes,
            const std::function<bool(const v1::SceneChunk&)>& write) const;
  // Each add() is a use of the scene (a live job); when its last use is released the scene
  // is forgotten, but stays on disk: ended jobs keep it (a requeue goes on with it) until
  // they are deleted (remove_if_unused).
  void release(const std::string& hash);

 private:
  struct Kept {
    v1::SceneManifest manifest;
    int uses = 0;
  };
  SceneSource source(const std::string& hash, const v1::SceneManifest& m) const;  // its files on disk
  // One more use of the scene `hash` if it is kept (false: not kept), `check` run on the
  // kept copy; a refusal gives the use back and throws as keep() does.
  bool use_kept(const std::string& hash, const Check& check);

  std::string dir_;
  SceneLoads loads_;
  mutable std::mutex mu_;
  std::map<std::string, Kept> scenes_;
};

// What the coordinator serves workers from the store: a kept scene's manifest, its pieces.
// Throw RequestError (kNotFound: not kept, or released while read; kInvalidArgument).
v1::SceneManifest served_manifest(const SceneStore& scenes, const std::string& hash);
void serve_scene(const SceneStore& scenes, const v1::FetchSceneRequest& req, size_t chunk_bytes,
                 const std::function<bool(const v1::SceneChunk&)>& write);

}  // namespace tessera
