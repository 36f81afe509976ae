// Scenes in pieces, for the streams that carry them (UploadScene from the client,
// FetchSceneChunks to workers: tessera.proto's SceneChunk): the manifest first (the main
// file; each file's path and size; the content hash), then each file's bytes in the
// manifest's order, a piece at most a chunk. The sender reads a piece at a time from disk
// and the receiver writes each to disk as it comes, checking it against the manifest, so a
// scene of any size passes through a fixed amount of memory and under any message limit.
#pragma once

#include <cstdint>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "tessera.grpc.pb.h"

namespace tessera {

constexpr size_t kSceneChunkBytes = size_t(1) << 20;      // a piece, as senders cut them
constexpr size_t kMaxSceneChunkBytes = size_t(16) << 20;  // the most a receiver takes in one
constexpr size_t kMaxSceneFiles = size_t(1) << 16;
// The most a manifest may declare, each file and all together (1 PiB: far past any
// owner's limit, so that the limit's check, not a wrapped sum, is what refuses).
constexpr uint64_t kMaxSceneManifestBytes = uint64_t(1) << 50;

// What a file or folder costs on disk at least: what the weight below charges.
constexpr uint64_t kSceneDiskBlock = 4096;

// What a bundle weighs against its owner's limit: its files' paths and sizes, each size
// rounded up to whole disk blocks (an empty file a block), and a block for each folder the
// paths make. Charged as the disk is used: 256 empty files a kilobyte deep made 130,000
// folders and 534 MB on disk when only paths and sizes counted (261 KB). Sums saturate.
// The paths are kept as views, so they must outlive the weight (a manifest's or a
// bundle's); the folders are counted from them sorted, without a copy or a set of every
// prefix (65,536 deep paths make tens of millions: gigabytes).
class SceneWeight {
 public:
  void add(const std::string& path, uint64_t size);
  uint64_t file_bytes() const { return files_; }  // the paths and blocks of the files alone
  uint64_t bytes() const;                         // and the folders'

 private:
  std::vector<std::string_view> paths_;
  uint64_t files_ = 0;
};

// bundle_hash() a piece at a time: the same digest for the same bundle.
class BundleHasher {
 public:
  explicit BundleHasher(const std::string& main_file);
  ~BundleHasher();
  BundleHasher(const BundleHasher&) = delete;
  BundleHasher& operator=(const BundleHasher&) = delete;
  // A file begins: then exactly `size` bytes of update().
  void file(const std::string& path, uint64_t size);
  void update(const void* data, size_t n);
  std::string digest() const;

 private:
  struct State;
  std::unique_ptr<State> st_;
};

// Checks a manifest before anything is written: paths inside the bundle's folder, in
// normal form, each once, none also a folder of another; the main file among them; at
// most kMaxSceneFiles files of kMaxSceneManifestBytes at most together; a hash of 32 hex
// digits. Throws WireError naming the problem. Returns what the scene weighs against its owner's limit
// (SceneWeight).
uint64_t check_manifest(const v1::SceneManifest& m);

// A bundle's files on disk, to send.
struct SceneSource {
  v1::SceneManifest manifest;
  std::vector<std::string> paths;  // on disk, one per manifest file
};
// The bundle of `files` (path in the bundle, path on disk), its main file `main_file`,
// with each file's size and the content hash (one read of every file). Throws
// std::runtime_error naming a file it cannot read.
SceneSource scene_source(const std::string& main_file, const std::vector<std::pair<std::string, std::string>>& files);
// Reads the files and returns their bundle_hash (the manifest's own is not looked at).
// Throws std::runtime_error when a file cannot be read or is not its listed size.
std::string hash_files(const SceneSource& s);
// Calls `send` with each piece from byte `offset` of file `file` on, in order, each at most
// `chunk_bytes`; returns false as soon as `send` does. Throws WireError for a start past
// the end, std::runtime_error when a file cannot be read or is shorter than listed.
bool send_pieces(const SceneSource& s, uint32_t file, uint64_t offset, size_t chunk_bytes,
                 const std::function<bool(v1::SceneChunk&)>& send);

// Writes a scene's pieces into a folder as they come, each checked against the manifest:
// the piece expected next (in order, no gaps, none past its file's size), then, once all
// came, the content hash. Files of size 0 are made as the pieces pass them.
class SceneReceiver {
 public:
  // check_manifest()s `m` and makes `dir`. Throws WireError. Messages begin with `what`.
  SceneReceiver(std::string dir, v1::SceneManifest m, std::string what = "scene upload");
  const v1::SceneManifest& manifest() const { return m_; }
  uint64_t bytes() const { return bytes_; }  // check_manifest's
  // Throws WireError naming what is wrong with the piece, std::runtime_error when the disk
  // refuses it.
  void add(const v1::SceneChunk& piece);
  // The next byte expected: where a stream cut short goes on.
  uint32_t next_file() const { return file_; }
  uint64_t next_offset() const { return offset_; }
  bool complete() const { return file_ == uint32_t(m_.files_size()); }
  // Where the pieces stopped, for messages: "file 'a.dae' at byte 10 of 7475".
  std::string position() const;
  // Throws WireError unless every byte came and their hash is the manifest's.
  void finish();

 private:
  void open(const v1::SceneFileInfo& f);
  // Throws naming the file, where it goes on disk and why (errno).
  [[noreturn]] void cannot_write(const v1::SceneFileInfo& f) const;
  void settle();  // past a file with all its bytes, and files of size 0

  std::string dir_;
  v1::SceneManifest m_;
  std::string what_;
  uint64_t bytes_ = 0;
  BundleHasher hasher_;
  uint32_t file_ = 0;
  uint64_t offset_ = 0;
  std::ofstream out_;  // file_'s, once its first piece came
};

}  // namespace tessera
