#include "server/scene_store.h"

#include <atomic>
#include <filesystem>
#include <fstream>

#include "core/scene/load.h"
#include "core/scene/scene_error.h"

namespace tessera {

namespace fs = std::filesystem;

SceneStore::SceneStore(std::string dir) : dir_(std::move(dir)) { fs::create_directories(dir_); }

std::string SceneStore::add(const std::string& main_file, const SceneFiles& files,
                            const std::function<void(const Scene&)>& check) {
  const std::string hash = bundle_hash(main_file, files);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (scenes_.count(hash)) {  // the same bytes were checked before
      ++uses_[hash];
      return hash;
    }
  }
  // Unpacked into a folder of its own, so that two submits of one scene never share
  // files, loaded, and removed: the bundle itself is what is kept.
  static std::atomic<uint64_t> staging_seq{0};
  const fs::path staging = fs::path(dir_) / (hash + ".staging-" + std::to_string(++staging_seq));
  std::error_code ec;
  try {
    const Scene scene = load_scene(unpack_bundle(staging.string(), main_file, files));  // outside the lock: slow
    if (check) check(scene);
  } catch (const SceneError& e) {
    fs::remove_all(staging, ec);
    throw SceneError(main_file, e.element(), e.reason());
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  fs::remove_all(staging, ec);
  v1::SceneBundle b;
  b.set_main_file(main_file);
  *b.mutable_files() = files;
  // Written under a name of its own and renamed into place: two adds of the same bytes
  // write the same file, and a reader sees one whole.
  const fs::path kept = fs::path(dir_) / (hash + ".bundle");
  const fs::path tmp = staging.string() + ".bundle";
  {
    std::ofstream out(tmp, std::ios::binary);
    if (!b.SerializeToOstream(&out) || !out.flush()) {
      fs::remove(tmp, ec);
      throw std::runtime_error("cannot keep the scene on the coordinator's disk");
    }
  }
  std::lock_guard<std::mutex> lock(mu_);  // renamed under it: a release() of the same bytes removes it before or after
  fs::rename(tmp, kept, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw std::runtime_error("cannot keep the scene on the coordinator's disk");
  }
  scenes_[hash] = std::move(b);
  ++uses_[hash];
  return hash;
}

uint64_t bundle_bytes(const SceneFiles& files) {
  uint64_t n = 0;
  for (const v1::SceneFile& f : files) n += f.path().size() + f.content().size();
  return n;
}

uint64_t SceneStore::restore(const std::string& hash) {
  const fs::path kept = fs::path(dir_) / (hash + ".bundle");
  v1::SceneBundle b;
  std::ifstream in(kept, std::ios::binary);
  if (!in || !b.ParseFromIstream(&in)) throw std::runtime_error("its scene is missing from the data folder");
  if (bundle_hash(b.main_file(), b.files()) != hash)
    throw std::runtime_error("its scene in the data folder is damaged");
  add(b.main_file(), b.files());
  return bundle_bytes(b.files());
}

void SceneStore::remove_unused() {
  std::lock_guard<std::mutex> lock(mu_);
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    const std::string name = entry.path().filename().string();
    const size_t dot = name.find('.');
    if (name.substr(dot == std::string::npos ? name.size() : dot) == ".bundle" && scenes_.count(name.substr(0, dot)))
      continue;
    std::error_code rm;
    fs::remove_all(entry.path(), rm);
  }
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
    // Under the lock: an add() of the same bytes waits, then checks afresh.
    std::error_code ec;
    fs::remove(fs::path(dir_) / (hash + ".bundle"), ec);
  }
}

}  // namespace tessera
