// A worker's scenes and renderers: each scene fetched once per content hash, in pieces
// written to disk as they come (proto/scene_chunks.h; a fetch cut short goes on from the
// first byte it lacks) and kept there (a restarted worker does not fetch it again), loaded
// once, and a renderer built per (scene, settings), a few of them kept. Renderers of frames
// of one sequence share one acceleration structure.
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "core/render/tile_renderer.h"
#include "core/scene/scene.h"
#include "tessera.grpc.pb.h"

namespace tessera::worker {

// A scene and a renderer for one (scene, settings).
struct PreparedRenderer {
  std::shared_ptr<Scene> scene;  // outlives the renderer, which refers to it
  std::unique_ptr<TileRenderer> renderer;
  std::string base_key;  // scene and settings but the frame: renderers sharing one BVH
};

// The coordinator refused the scene's download for now (RESOURCE_EXHAUSTED: its bound on
// one worker's, or one address's, open downloads) through every attempt: not the task's
// fault, so the task goes back without an error (a failure would count against its job).
class SceneBusy : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The cache's bounds. On disk: after each fetch, the scene folders least recently used are
// removed until the folder holds at most `max_disk_bytes` (0: no bound), never the scene
// just fetched, one any worker sharing the folder is loading or holds in memory (a renderer
// of other settings may read its files again: each holds a lock on the folder's marker),
// nor one used in the last `min_idle_seconds`. In memory: after a
// renderer is built, the oldest kept ones are dropped while the process's resident memory
// is above `max_memory_bytes` (0: no bound), the newest always kept (tasks in flight
// hold their own).
struct SceneCacheBounds {
  uint64_t max_disk_bytes = 0;
  double min_idle_seconds = 3600;
  uint64_t max_memory_bytes = 0;
};

class SceneCache {
 public:
  // Streams a scene from the coordinator (FetchSceneChunks) from the request's (file,
  // offset) on: calls `piece` with each message in order (it may throw, which ends the
  // call) and returns the call's status.
  using Piece = std::function<void(const v1::SceneChunk&)>;
  using FetchChunks = std::function<grpc::Status(const v1::FetchSceneRequest& request, const Piece& piece)>;
  static constexpr size_t kKeptRenderers = 8;  // jobs alternate by priority, frames follow each other
  // Calls in a row that find the coordinator out of reach (or busy) without bringing a byte.
  static constexpr int kFetchAttempts = 4;

  using Bounds = SceneCacheBounds;
  // Removes what dead workers' downloads left in `dir`.
  SceneCache(std::string dir, FetchChunks fetch, Bounds bound = {});

  // The renderer for a task's scene and settings. Throws WireError (a bad hash, pieces or
  // bytes that do not match it), SceneError and SettingsError (a scene or settings this
  // worker cannot render), SceneBusy, or std::runtime_error saying why the fetch failed.
  std::shared_ptr<const PreparedRenderer> prepare(const v1::Task& task);
  // Scenes loaded and still held (by a kept renderer or a task in flight).
  size_t scenes_held() const;
  size_t renderers_kept() const { return prepared_.size(); }
  // The free bytes of the cache's file system (statvfs; a test seam).
  std::function<std::optional<uint64_t>()> free_disk_bytes;

 private:
  std::shared_ptr<Scene> scene(const std::string& hash);  // loaded once per content hash
  void fetch(const std::string& hash);                    // into the disk cache
  // Removes scene folders, least recently used first, until the cache is within its bound
  // (never throws: a filesystem error is logged, and the bound waits for the next fetch).
  void trim(const std::string& fetched);
  // `to_free` > 0: removes unused scenes (any idle time, never one a worker holds), least
  // recently used first, until that many bytes are freed, whatever the bound.
  void trim_folder(const std::string& fetched, uint64_t to_free = 0);
  // Before a scene of `need` bytes is written: where the disk has less room, unused scenes
  // go first; where it still would not fit, the fetch is refused naming the sizes (a full
  // disk failed the task midway as "cannot write", the cache never making room).
  void make_room(const std::string& hash, uint64_t need);
  // Marks the scene used (its marker's time: the disk bound's order, for every worker).
  void mark_used(const std::string& hash) const;

  std::string dir_;
  FetchChunks fetch_;
  Bounds bound_;
  // By content hash, while something holds them: a scene goes with the last renderer that
  // uses it (it held every scene the worker had ever loaded, for good: a farm running for
  // months grew its workers' memory scene by scene), and is loaded from disk again if a
  // later task needs it.
  std::map<std::string, std::weak_ptr<Scene>> scenes_;
  std::map<std::string, std::shared_ptr<const PreparedRenderer>> prepared_;
  std::deque<std::string> prepared_order_;
};

}  // namespace tessera::worker
