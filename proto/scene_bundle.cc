#include "scene_bundle.h"

#include <xxhash.h>

#include <cstdio>
#include <filesystem>

#include "core/io/files.h"
#include "core/scene/load.h"
#include "wire.h"

namespace tessera {

namespace fs = std::filesystem;

std::string bundle_hash(const std::string& main_file, const SceneFiles& files) {
  XXH3_state_t* st = XXH3_createState();
  XXH3_128bits_reset(st);
  auto add = [&](const std::string& s) {
    const uint64_t n = s.size();
    XXH3_128bits_update(st, &n, sizeof n);
    XXH3_128bits_update(st, s.data(), s.size());
  };
  add(main_file);
  for (const v1::SceneFile& f : files) {
    add(f.path());
    add(f.content());
  }
  const XXH128_hash_t h = XXH3_128bits_digest(st);
  XXH3_freeState(st);
  char buf[33];
  std::snprintf(buf, sizeof buf, "%016llx%016llx", (unsigned long long)h.high64, (unsigned long long)h.low64);
  return buf;
}

namespace {

bool safe_relative(const std::string& p) {
  if (p.empty() || p.size() > 1024 || p[0] == '/' || p.find('\0') != std::string::npos) return false;
  for (const auto& part : fs::path(p))
    if (part == ".." || part == ".") return false;
  return true;
}

}  // namespace

std::vector<std::pair<std::string, std::string>> scene_bundle_files(const std::string& path) {
  const std::vector<std::string> extra = scene_files(path);
  std::vector<std::pair<std::string, std::string>> files{{fs::path(path).filename().string(), path}};
  for (const std::string& rel : extra) {
    if (!safe_relative(rel)) throw std::runtime_error(path + ": '" + rel + "' is not a path inside the scene's folder");
    files.emplace_back(rel, (fs::path(path).parent_path() / rel).string());
  }
  return files;
}

void pack_scene(const std::string& path, std::string* main_file, SceneFiles* files) {
  const auto listed = scene_bundle_files(path);
  *main_file = listed[0].first;
  for (const auto& [rel, source] : listed) {
    v1::SceneFile* f = files->Add();
    f->set_path(rel);
    f->set_content(read_file_bytes(source));
  }
}

std::string unpack_bundle(const std::string& dir, const std::string& main_file, const SceneFiles& files) {
  bool has_main = false;
  for (const v1::SceneFile& f : files) {
    if (!safe_relative(f.path())) throw WireError("scene bundle: unsafe file path '" + f.path() + "'");
    has_main |= f.path() == main_file;
  }
  if (!has_main) throw WireError("scene bundle: main file '" + main_file + "' is not among its files");
  fs::create_directories(dir);
  for (const v1::SceneFile& f : files) {
    const fs::path p = fs::path(dir) / f.path();
    fs::create_directories(p.parent_path());
    write_file_atomic(p.string(), f.content());
  }
  return (fs::path(dir) / main_file).string();
}

}  // namespace tessera
