// Whole-file reads and atomic whole-file writes.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "core/io/interrupt_cleanup.h"

namespace tessera {

// Throws std::runtime_error naming the path.
std::string read_file_bytes(const std::string& path);

// The temporary a file is written to before it is renamed into place: PATH + suffix, or,
// once this process called use_unique_temporaries(), PATH.PID + suffix. The tessera
// command does: two of them writing one output (two fetches, two renders with the same -f)
// shared one temporary, each truncating and writing into the other's, and one of them said
// it had succeeded with the other's image. (A coordinator's folder has one writer, and its
// restart sweeps the fixed names: it keeps them.)
std::string temporary_path(const std::string& path, const char* suffix = ".tmp");
void use_unique_temporaries(bool on = true);

struct AtomicWrite {
  // fsync the file before the rename and its folder after: the new bytes survive a power
  // cut, not only a killed process (film checkpoints).
  bool durable = false;
  // Runs between the temporary file being complete and its rename (a test seam).
  std::function<void()> before_rename;
};
// Writes to PATH.tmp (temporary_path) and renames it into place: a reader sees the old file or the new one,
// never half of one. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, const std::string& bytes, const AtomicWrite& how = {});

// The same, written piece by piece: PATH.tmp is filled by append() and renamed into place
// by commit(); destroyed before commit() (an error, an exception) it removes PATH.tmp, and
// so does a signal that ends a process with install_interrupt_cleanup() (Ctrl-C).
// Throws std::runtime_error naming the path.
class AtomicFile {
 public:
  explicit AtomicFile(std::string path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  void append(const char* data, size_t n);
  void append(const std::string& bytes) { append(bytes.data(), bytes.size()); }
  uint64_t size() const { return size_; }
  void commit(const AtomicWrite& how = {});

 private:
  [[noreturn]] void fail(const std::string& what);
  std::string path_, tmp_;
  RemoveOnInterrupt cleanup_{tmp_};
  int fd_ = -1;
  uint64_t size_ = 0;
};

// Copies `from` to `to` as write_file_atomic writes, a piece at a time (an 8K EXR with its
// layers is never whole in memory). Throws std::runtime_error naming the path at fault.
void copy_file_atomic(const std::string& from, const std::string& to);

// Renames `tmp` to `path`, then (durable) syncs the folder. Throws naming `path`.
void commit_file(const std::string& tmp, const std::string& path, const AtomicWrite& how = {});

// Makes the folder `path` is in, and its parents (nothing for a bare file name). Throws
// std::runtime_error naming both.
void make_parent_folder(const std::string& path);

// Removes a folder and everything in it (nothing if it is absent); returns the bytes its
// files held. Throws std::runtime_error naming the folder when it cannot be removed.
uint64_t remove_folder(const std::string& path);

}  // namespace tessera
