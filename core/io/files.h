// Whole-file reads and atomic whole-file writes.
#pragma once

#include <functional>
#include <string>

namespace tessera {

// Throws std::runtime_error naming the path.
std::string read_file_bytes(const std::string& path);

struct AtomicWrite {
  // fsync the file before the rename and its folder after: the new bytes survive a power
  // cut, not only a killed process (film checkpoints).
  bool durable = false;
  // Runs between the temporary file being complete and its rename (a test seam).
  std::function<void()> before_rename;
};
// Writes to PATH.tmp and renames it into place: a reader sees the old file or the new one,
// never half of one. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, const std::string& bytes, const AtomicWrite& how = {});

}  // namespace tessera
