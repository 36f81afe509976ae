#include "server/scene_store.h"

#include <atomic>
#include <filesystem>

#include "core/scene/load.h"
#include "core/scene/scene_error.h"

namespace tessera {

namespace fs = std::filesystem;

SceneStore::SceneStore(std::string dir) : dir_(std::move(dir)) { fs::create_directories(dir_); }

std::string SceneStore::add(const std::string& main_file, const SceneFiles& files) {
  const std::string hash = bundle_hash(main_file, files);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (scenes_.count(hash)) {  // the same bytes were checked before
      ++uses_[hash];
      return hash;
    }
  }
  // Unpacked into a folder of its own, so that two submits of one scene never share
  // files, then renamed into place (the first to finish wins; the bytes are the same).
  static std::atomic<uint64_t> staging_seq{0};
  const fs::path dir = fs::path(dir_) / hash;
  const fs::path staging = fs::path(dir_) / (hash + ".staging-" + std::to_string(++staging_seq));
  std::error_code ec;
  try {
    (void)load_scene(unpack_bundle(staging.string(), main_file, files));  // outside the lock: slow
  } catch (const SceneError& e) {
    fs::remove_all(staging, ec);
    throw SceneError(main_file, e.element(), e.reason());
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  fs::rename(staging, dir, ec);
  if (ec) fs::remove_all(staging, ec);  // already there
  std::lock_guard<std::mutex> lock(mu_);
  v1::SceneBundle& b = scenes_[hash];
  b.set_main_file(main_file);
  *b.mutable_files() = files;
  ++uses_[hash];
  return hash;
}

v1::SceneBundle SceneStore::get(const std::string& hash) const {
  std::lock_guard<std::mutex> lock(mu_);
  return scenes_.at(hash);
}

void SceneStore::release(const std::string& hash) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = uses_.find(hash);
    if (it == uses_.end() || --it->second > 0) return;
    uses_.erase(it);
    scenes_.erase(hash);
    // Under the lock: an add() of the same bytes waits, then unpacks afresh.
    std::error_code ec;
    fs::remove_all(fs::path(dir_) / hash, ec);
  }
}

}  // namespace tessera
