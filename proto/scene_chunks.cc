#include "scene_chunks.h"

#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <set>

#include "core/util/saturating.h"
#include "wire.h"

namespace tessera {

namespace fs = std::filesystem;

// ---- the hash ----

struct BundleHasher::State {
  XXH3_state_t* xxh = XXH3_createState();
  ~State() { XXH3_freeState(xxh); }
  void add(const std::string& s) {  // as bundle_hash adds a string: its length, then it
    const uint64_t n = s.size();
    XXH3_128bits_update(xxh, &n, sizeof n);
    XXH3_128bits_update(xxh, s.data(), s.size());
  }
};

BundleHasher::BundleHasher(const std::string& main_file) : st_(std::make_unique<State>()) {
  XXH3_128bits_reset(st_->xxh);
  st_->add(main_file);
}

BundleHasher::~BundleHasher() = default;

void BundleHasher::file(const std::string& path, uint64_t size) {
  st_->add(path);
  XXH3_128bits_update(st_->xxh, &size, sizeof size);
}

void BundleHasher::update(const void* data, size_t n) { XXH3_128bits_update(st_->xxh, data, n); }

std::string BundleHasher::digest() const {
  const XXH128_hash_t h = XXH3_128bits_digest(st_->xxh);
  char buf[33];
  std::snprintf(buf, sizeof buf, "%016llx%016llx", (unsigned long long)h.high64, (unsigned long long)h.low64);
  return buf;
}

// ---- the manifest ----

namespace {

// Relative, in normal form ("a/b.png": no empty, "." or ".." parts), not too long: a path
// that stays inside the scene's folder and names one file one way.
bool normal_relative(const std::string& p) {
  if (p.empty() || p.size() > 1024 || p.find('\0') != std::string::npos) return false;
  for (size_t start = 0;;) {
    const size_t slash = p.find('/', start);
    const std::string part = p.substr(start, slash == std::string::npos ? std::string::npos : slash - start);
    if (part.empty() || part == "." || part == "..") return false;
    if (slash == std::string::npos) return true;
    start = slash + 1;
  }
}

std::string quoted(const std::string& path) {
  std::string q(1, '\'');
  q.append(path, 0, 256);
  q += '\'';
  return q;
}

}  // namespace

void SceneWeight::add(const std::string& path, uint64_t size) {
  const uint64_t blocks = size == 0 ? 1 : size / kSceneDiskBlock + (size % kSceneDiskBlock != 0);
  files_ = saturating_add(files_, saturating_add(path.size(), saturating_mul(blocks, kSceneDiskBlock)));
  paths_.push_back(path);
}

uint64_t SceneWeight::bytes() const {
  // The folders, each once, without a set of them (65,536 paths of 500 one-letter parts
  // make 33 M prefixes): in sorted order the paths under a folder are adjacent, so a
  // path's folders are new but for those it shares with the path before it.
  std::vector<std::string_view> sorted = paths_;
  std::sort(sorted.begin(), sorted.end());
  uint64_t folders = 0;
  std::string_view prev;
  for (const std::string_view p : sorted) {
    size_t shared = 0;  // folders of p that prev has too: prefixes ending at a '/' both share
    for (size_t i = 0; i < p.size() && i < prev.size() && p[i] == prev[i]; ++i)
      if (p[i] == '/') ++shared;
    folders += uint64_t(std::count(p.begin(), p.end(), '/')) - shared;
    prev = p;
  }
  return saturating_add(files_, saturating_mul(folders, kSceneDiskBlock));
}

uint64_t check_manifest(const v1::SceneManifest& m) {
  const auto& h = m.scene_hash();
  if (h.size() != 32 || h.find_first_not_of("0123456789abcdef") != std::string::npos)
    throw WireError("scene manifest: bad scene hash " + quoted(h));
  if (size_t(m.files_size()) > kMaxSceneFiles)
    throw WireError("scene manifest: " + std::to_string(m.files_size()) + " files; at most " +
                    std::to_string(kMaxSceneFiles));
  std::set<std::string> paths;
  SceneWeight weight;
  for (const v1::SceneFileInfo& f : m.files()) {
    if (!normal_relative(f.path()))
      throw WireError("scene manifest: unsafe file path " + quoted(f.path()) +
                      " (a path inside the scene's folder, without '..', '.' or empty parts)");
    if (!paths.insert(f.path()).second) throw WireError("scene manifest: file " + quoted(f.path()) + " listed twice");
    if (f.size() > kMaxSceneManifestBytes)
      throw WireError("scene manifest: file " + quoted(f.path()) + " declares " + std::to_string(f.size()) +
                      " bytes; at most " + std::to_string(kMaxSceneManifestBytes));
    weight.add(f.path(), f.size());
    if (weight.file_bytes() > kMaxSceneManifestBytes)
      throw WireError("scene manifest: its files declare over " + std::to_string(kMaxSceneManifestBytes) +
                      " bytes together");
  }
  for (const std::string& p : paths)  // "a" and "a/b": one would have to be a file and a folder
    for (size_t slash = p.find('/'); slash != std::string::npos; slash = p.find('/', slash + 1))
      if (paths.count(p.substr(0, slash)))
        throw WireError("scene manifest: " + quoted(p.substr(0, slash)) + " is both a file and a folder");
  if (!paths.count(m.main_file()))
    throw WireError("scene manifest: main file " + quoted(m.main_file()) + " is not among its files");
  return weight.bytes();
}

// ---- sending ----

std::string hash_files(const SceneSource& s) {
  BundleHasher hasher(s.manifest.main_file());
  std::string buf(kSceneChunkBytes, '\0');
  for (int i = 0; i < s.manifest.files_size(); ++i) {
    const v1::SceneFileInfo& f = s.manifest.files(i);
    hasher.file(f.path(), f.size());
    std::ifstream in(s.paths[size_t(i)], std::ios::binary);
    if (!in) throw std::runtime_error(s.paths[size_t(i)] + ": cannot open file");
    for (uint64_t left = f.size(); left > 0;) {
      const size_t n = size_t(std::min<uint64_t>(left, buf.size()));
      if (!in.read(buf.data(), std::streamsize(n)))
        throw std::runtime_error(s.paths[size_t(i)] + ": shorter than its " + std::to_string(f.size()) + " bytes");
      hasher.update(buf.data(), n);
      left -= n;
    }
  }
  return hasher.digest();
}

SceneSource scene_source(const std::string& main_file, const std::vector<std::pair<std::string, std::string>>& files) {
  SceneSource s;
  s.manifest.set_main_file(main_file);
  for (const auto& [rel, disk] : files) {
    std::error_code ec;
    const uint64_t size = fs::file_size(disk, ec);
    if (ec) throw std::runtime_error(disk + ": cannot open file");
    v1::SceneFileInfo* f = s.manifest.add_files();
    f->set_path(rel);
    f->set_size(size);
    s.paths.push_back(disk);
  }
  s.manifest.set_scene_hash(hash_files(s));
  return s;
}

bool send_pieces(const SceneSource& s, uint32_t file, uint64_t offset, size_t chunk_bytes,
                 const std::function<bool(v1::SceneChunk&)>& send) {
  const auto& files = s.manifest.files();
  if (file > uint32_t(files.size()) || (file < uint32_t(files.size()) && offset > files[int(file)].size()) ||
      (file == uint32_t(files.size()) && offset != 0))
    throw WireError("scene " + s.manifest.scene_hash() + ": no byte " + std::to_string(offset) + " in file #" +
                    std::to_string(file));
  chunk_bytes = std::max<size_t>(1, chunk_bytes);
  v1::SceneChunk piece;
  for (uint32_t i = file; i < uint32_t(files.size()); ++i, offset = 0) {
    const uint64_t size = files[int(i)].size();
    if (offset == size) continue;
    std::ifstream in(s.paths[i], std::ios::binary);
    if (!in || !in.seekg(std::streamoff(offset))) throw std::runtime_error(s.paths[i] + ": cannot open file");
    while (offset < size) {
      const size_t n = size_t(std::min<uint64_t>(size - offset, chunk_bytes));
      std::string* data = piece.mutable_data();
      data->resize(n);
      if (!in.read(data->data(), std::streamsize(n)))
        throw std::runtime_error(s.paths[i] + ": shorter than its " + std::to_string(size) + " bytes");
      piece.set_file(i);
      piece.set_offset(offset);
      if (!send(piece)) return false;
      offset += n;
    }
  }
  return true;
}

// ---- receiving ----

SceneReceiver::SceneReceiver(std::string dir, v1::SceneManifest m, std::string what)
    : dir_(std::move(dir)),
      m_(std::move(m)),
      what_(std::move(what)),
      bytes_(check_manifest(m_)),
      hasher_(m_.main_file()) {
  fs::create_directories(dir_);
  hasher_.file(m_.files(0).path(), m_.files(0).size());  // (check_manifest: the main file is one)
  settle();
}

std::string SceneReceiver::position() const {
  if (complete()) return "the end of its last file";
  const v1::SceneFileInfo& f = m_.files(int(file_));
  return "file " + quoted(f.path()) + " at byte " + std::to_string(offset_) + " of " + std::to_string(f.size());
}

void SceneReceiver::cannot_write(const v1::SceneFileInfo& f) const {
  // errno as the failed call left it: "No space left on device" is what an operator needs.
  const int e = errno;
  throw std::runtime_error("cannot write scene file " + quoted(f.path()) + " to " +
                           (fs::path(dir_) / f.path()).string() +
                           (e ? std::string(": ") + std::strerror(e) : std::string()));
}

void SceneReceiver::open(const v1::SceneFileInfo& f) {
  const fs::path p = fs::path(dir_) / f.path();
  std::error_code ec;
  fs::create_directories(p.parent_path(), ec);
  errno = 0;
  out_ = std::ofstream(p, std::ios::binary | std::ios::trunc);
  if (!out_) cannot_write(f);
}

void SceneReceiver::settle() {
  while (!complete()) {
    const v1::SceneFileInfo& f = m_.files(int(file_));
    if (offset_ < f.size()) return;
    if (!out_.is_open()) open(f);  // a file of size 0
    errno = 0;
    out_.close();
    if (!out_) cannot_write(f);
    ++file_;
    offset_ = 0;
    if (!complete()) hasher_.file(m_.files(int(file_)).path(), m_.files(int(file_)).size());
  }
}

void SceneReceiver::add(const v1::SceneChunk& piece) {
  if (piece.has_manifest()) throw WireError(what_ + ": a second manifest at " + position());
  const uint64_t n = piece.data().size();
  if (n == 0) throw WireError(what_ + ": an empty piece at " + position());
  if (n > kMaxSceneChunkBytes)
    throw WireError(what_ + ": a piece of " + std::to_string(n) + " bytes; at most " +
                    std::to_string(kMaxSceneChunkBytes));
  if (piece.file() >= uint32_t(m_.files_size()))
    throw WireError(what_ + ": a piece of file #" + std::to_string(piece.file()) + "; the manifest lists " +
                    std::to_string(m_.files_size()) + " files");
  const v1::SceneFileInfo& f = m_.files(int(piece.file()));
  if (piece.offset() + n > f.size() || piece.offset() > f.size())
    throw WireError(what_ + ": file " + quoted(f.path()) + ": " + std::to_string(n) + " bytes at byte " +
                    std::to_string(piece.offset()) + " pass its declared size, " + std::to_string(f.size()));
  if (piece.file() != file_ || piece.offset() != offset_)
    throw WireError(what_ + ": a piece of file " + quoted(f.path()) + " at byte " + std::to_string(piece.offset()) +
                    " out of order (expected " + position() + ")");
  if (!out_.is_open()) open(f);
  errno = 0;
  if (!out_.write(piece.data().data(), std::streamsize(n))) cannot_write(f);
  hasher_.update(piece.data().data(), n);
  offset_ += n;
  settle();
}

void SceneReceiver::finish() {
  if (!complete()) throw WireError(what_ + ": it ended at " + position());
  const std::string got = hasher_.digest();
  if (got != m_.scene_hash())
    throw WireError(what_ + ": its bytes hash to " + got + ", not to the manifest's " + m_.scene_hash() +
                    " (a file changed while it was sent, or the bytes were damaged)");
}

}  // namespace tessera
