// Whole-file reads and atomic whole-file writes.
#pragma once

#include <string>

namespace tessera {

// Throws std::runtime_error naming the path.
std::string read_file_bytes(const std::string& path);
// Writes to PATH.tmp and renames it into place: a reader sees the old file or the new one,
// never half of one. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, const std::string& bytes);

}  // namespace tessera
