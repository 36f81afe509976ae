#include "server/scene_store.h"

#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "core/io/files.h"
#include "core/scene/load.h"
#include "core/scene/scene_error.h"
#include "server/data_marker.h"
#include "server/request_error.h"
#include "wire.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

// Removes a folder when it goes out of scope (a staged scene, whatever became of it).
struct RemoveAll {
  fs::path dir;
  ~RemoveAll() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

}  // namespace

uint64_t bundle_bytes(const SceneFiles& files) {
  SceneWeight weight;
  for (const v1::SceneFile& f : files) weight.add(f.path(), f.content().size());
  return weight.bytes();
}

SceneStore::SceneStore(std::string dir, size_t loads_at_once) : dir_(std::move(dir)), loads_(loads_at_once) {
  fs::create_directories(dir_);
}

std::string SceneStore::staging_folder(const std::string& name) const {
  static std::atomic<uint64_t> seq{0};
  return (fs::path(dir_) / (name + ".staging-" + std::to_string(++seq))).string();
}

SceneSource SceneStore::source(const std::string& hash, const v1::SceneManifest& m) const {
  SceneSource s;
  s.manifest = m;
  for (const v1::SceneFileInfo& f : m.files()) s.paths.push_back((fs::path(dir_) / hash / "files" / f.path()).string());
  return s;
}

std::string SceneStore::add(const std::string& main_file, const SceneFiles& files, const Check& check) {
  v1::SceneManifest m;
  m.set_main_file(main_file);
  m.set_scene_hash(bundle_hash(main_file, files));
  for (const v1::SceneFile& f : files) {
    v1::SceneFileInfo* info = m.add_files();
    info->set_path(f.path());
    info->set_size(f.content().size());
  }
  check_manifest(m);  // throws WireError: an unsafe path, the main file missing
  if (use_kept(m.scene_hash(), check)) return m.scene_hash();  // the same bytes are kept
  const std::string staged = staging_folder(m.scene_hash());
  try {
    for (const v1::SceneFile& f : files) {
      const fs::path p = fs::path(staged) / "files" / f.path();
      fs::create_directories(p.parent_path());
      std::ofstream out(p, std::ios::binary);
      if (!out.write(f.content().data(), std::streamsize(f.content().size())) || !out.flush())
        throw std::runtime_error("cannot keep the scene on the coordinator's disk");
    }
  } catch (...) {
    std::error_code ec;
    fs::remove_all(staged, ec);
    throw;
  }
  return keep(staged, m, check);
}

std::string SceneStore::keep(const std::string& staged, const v1::SceneManifest& m, const Check& check) {
  const RemoveAll cleanup{staged};
  const std::string& hash = m.scene_hash();
  if (use_kept(hash, check)) return hash;
  try {
    in_turn([&] {  // outside the lock: slow
      const Scene scene = load_scene((fs::path(staged) / "files" / m.main_file()).string());
      if (check) check(scene);
    });
  } catch (const SceneError& e) {
    throw SceneError(m.main_file(), e.element(), e.reason());
  }
  write_file_atomic((fs::path(staged) / "manifest").string(), m.SerializeAsString());
  // Renamed into place under the lock: a release() of the same bytes removes it before or
  // after, and two keeps of the same bytes rename one of them.
  std::lock_guard<std::mutex> lock(mu_);
  if (auto it = scenes_.find(hash); it != scenes_.end()) {
    ++it->second.uses;
    return hash;
  }
  const fs::path kept = fs::path(dir_) / hash;
  std::error_code ec;
  fs::remove_all(kept, ec);  // a leftover no scene uses
  fs::rename(staged, kept, ec);
  if (ec) throw std::runtime_error("cannot keep the scene on the coordinator's disk: " + ec.message());
  scenes_[hash] = Kept{m, 1};
  return hash;
}

bool SceneStore::use_kept(const std::string& hash, const Check& check) {
  std::string main;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = scenes_.find(hash);
    if (it == scenes_.end()) return false;
    ++it->second.uses;
    main = it->second.manifest.main_file();
  }
  if (!check) return true;
  // Another job's settings were checked against these bytes, not this one's: load the kept
  // copy (outside the lock: slow) and check again; a refusal gives the use back.
  try {
    in_turn([&] { check(load_scene(main_path(hash))); });  // (kept while this use holds it)
  } catch (const SceneError& e) {
    release(hash);
    throw SceneError(main, e.element(), e.reason());
  } catch (...) {
    release(hash);
    throw;
  }
  return true;
}

uint64_t SceneStore::restore(const std::string& hash) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (auto it = scenes_.find(hash); it != scenes_.end()) {
      ++it->second.uses;
      return check_manifest(it->second.manifest);
    }
  }
  const fs::path dir = fs::path(dir_) / hash;
  v1::SceneManifest m;
  // (Named under the data folder: these reasons end up in job errors users see.)
  const std::string where = "scenes/" + hash;
  std::ifstream in(dir / "manifest", std::ios::binary);
  if (!in) {
    const int err = errno;
    std::error_code ec;
    if (fs::exists(dir / "manifest", ec) || ec)  // there, unreadable: not "missing" (the job failed for good)
      throw DataFolderError((dir / "manifest").string() + ": cannot read the scene's manifest: " + std::strerror(err) +
                            " (the coordinator must be able to read its data folder)");
    // Kept whole by a coordinator before protocol 5: unpacked once, as an add.
    const fs::path bundle = fs::path(dir_) / (hash + ".bundle");
    v1::SceneBundle b;
    std::ifstream old(bundle, std::ios::binary);
    if (!old || !b.ParseFromIstream(&old))
      throw std::runtime_error("its scene is missing from the data folder (" + where + ")");
    if (bundle_hash(b.main_file(), b.files()) != hash)
      throw std::runtime_error("its scene in the data folder is damaged (" + where + ".bundle: other bytes)");
    add(b.main_file(), b.files());
    fs::remove(bundle, ec);
    return bundle_bytes(b.files());
  }
  uint64_t bytes = 0;
  try {
    if (!m.ParseFromIstream(&in) || m.scene_hash() != hash) throw WireError("its manifest cannot be read");
    bytes = check_manifest(m);
    if (hash_files(source(hash, m)) != hash) throw WireError("its files are not the bytes it was given");
  } catch (const DataFolderError&) {
    throw;
  } catch (const std::exception& e) {  // unreadable, or other bytes
    throw std::runtime_error("its scene in the data folder is damaged (" + where + ": " + e.what() + ")");
  }
  try {
    in_turn([&] { return load_scene((dir / "files" / m.main_file()).string()); });  // as keep() checks it
  } catch (const SceneError& e) {
    throw SceneError(m.main_file(), e.element(), e.reason());
  }
  std::lock_guard<std::mutex> lock(mu_);
  ++scenes_[hash].uses;
  scenes_[hash].manifest = std::move(m);
  return bytes;
}

void SceneStore::remove_unused(const std::set<std::string>& referenced) {
  std::lock_guard<std::mutex> lock(mu_);
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_, ec)) {
    std::string name = entry.path().filename().string();
    // (A scene kept whole by a coordinator before protocol 5 is HASH.bundle: a job that
    // names it may need it again, a requeue of an ended one; it was removed.)
    if (name.size() > 7 && name.compare(name.size() - 7, 7, ".bundle") == 0) name.resize(name.size() - 7);
    if (scenes_.count(name) || referenced.count(name)) continue;
    std::error_code rm;
    fs::remove_all(entry.path(), rm);
  }
}

v1::SceneManifest SceneStore::manifest(const std::string& hash) const {
  std::lock_guard<std::mutex> lock(mu_);
  return scenes_.at(hash).manifest;
}

std::string SceneStore::main_path(const std::string& hash) const {
  std::lock_guard<std::mutex> lock(mu_);
  return (fs::path(dir_) / hash / "files" / scenes_.at(hash).manifest.main_file()).string();
}

bool SceneStore::send(const v1::FetchSceneRequest& req, size_t chunk_bytes,
                      const std::function<bool(const v1::SceneChunk&)>& write) const {
  const SceneSource s = source(req.scene_hash(), manifest(req.scene_hash()));
  v1::SceneChunk first;
  *first.mutable_manifest() = s.manifest;
  if (!write(first)) return false;
  return send_pieces(s, req.file(), req.offset(), chunk_bytes, [&](v1::SceneChunk& piece) { return write(piece); });
}

void SceneStore::release(const std::string& hash) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = scenes_.find(hash);
  if (it == scenes_.end() || --it->second.uses > 0) return;
  scenes_.erase(it);  // (its files stay: remove_if_unused)
}

uint64_t SceneStore::remove_if_unused(const std::string& hash) {
  if (hash.empty() || hash.find('/') != std::string::npos || hash.find("..") != std::string::npos) return 0;
  std::lock_guard<std::mutex> lock(mu_);  // a keep() of the same bytes waits, then checks afresh
  if (scenes_.count(hash)) return 0;
  std::error_code ec;
  fs::remove(fs::path(dir_) / (hash + ".bundle"), ec);  // kept whole before protocol 5
  try {
    return remove_folder((fs::path(dir_) / hash).string());
  } catch (const std::runtime_error&) {  // its files stay; the next start tries again
    return 0;
  }
}

v1::SceneManifest served_manifest(const SceneStore& scenes, const std::string& hash) {
  try {
    return scenes.manifest(hash);
  } catch (const std::out_of_range&) {
    throw RequestError(RequestError::Code::kNotFound, "no scene with hash " + hash);
  }
}

void serve_scene(const SceneStore& scenes, const v1::FetchSceneRequest& req, size_t chunk_bytes,
                 const std::function<bool(const v1::SceneChunk&)>& write) {
  try {
    scenes.send(req, chunk_bytes, write);
  } catch (const std::out_of_range&) {
    throw RequestError(RequestError::Code::kNotFound, "no scene with hash " + req.scene_hash());
  } catch (const WireError& e) {
    throw RequestError(RequestError::Code::kInvalidArgument, e.what());
  } catch (const std::runtime_error&) {
    served_manifest(scenes, req.scene_hash());  // released while it was read: not found
    throw;
  }
}

}  // namespace tessera
