// Scenes by content hash: checked when submitted, kept in memory for the workers that fetch
// them and on disk (<dir>/<hash>.bundle, the bundle as received) for a restarted
// coordinator.
#pragma once

#include <functional>
#include <map>
#include <mutex>
#include <string>

#include "core/scene/scene.h"
#include "scene_bundle.h"

namespace tessera {

// Paths and contents of a bundle's files: what a scene weighs against its owner's limit.
uint64_t bundle_bytes(const SceneFiles& files);

class SceneStore {
 public:
  explicit SceneStore(std::string dir);
  // Unpacks the bundle into a folder of its own and loads it as a worker will, so a bad scene is
  // refused here and never reaches a worker. Returns the content hash; the caller holds one
  // use of the scene until it calls release(). Throws WireError
  // (unsafe bundle) or SceneError naming the file as the user knows it, not by its path
  // here; a refused scene leaves nothing on disk. Thread-safe.
  // `check`, when given, is called with the loaded scene (a job's settings against it, say)
  // and may throw to refuse it.
  std::string add(const std::string& main_file, const SceneFiles& files,
                  const std::function<void(const Scene&)>& check = nullptr);
  // add() for a scene kept on disk by an earlier run; returns its bundle_bytes(). Throws
  // std::runtime_error (or what add() throws) when it is missing or its bytes no longer
  // have this hash.
  uint64_t restore(const std::string& hash);
  // Removes from the folder everything no scene in memory needs (after restore()s).
  void remove_unused();
  // Throws std::out_of_range for an unknown hash.
  v1::SceneBundle get(const std::string& hash) const;
  // Each add() is a use of the scene (a job); when its last use is released the scene
  // is forgotten, in memory and on disk.
  void release(const std::string& hash);

 private:
  std::string dir_;
  mutable std::mutex mu_;
  std::map<std::string, v1::SceneBundle> scenes_;
  std::map<std::string, int> uses_;
};

}  // namespace tessera
