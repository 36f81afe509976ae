#include "server/data_marker.h"

#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "core/io/files.h"

namespace tessera {

namespace fs = std::filesystem;

namespace {

constexpr const char* kMarker = "DATA-FOLDER";
constexpr const char* kOpen = "database: open";
constexpr const char* kClosed = "database: closed";

}  // namespace

void check_data_marker(const std::string& dir) {
  const fs::path marker = fs::path(dir) / kMarker;
  std::ifstream in(marker);
  if (!in) return;  // a new folder, or one from before markers: nothing to compare with
  std::stringstream text;
  text << in.rdbuf();
  const fs::path db = fs::path(dir) / "coordinator.db";
  if (!fs::exists(db))
    throw std::runtime_error(db.string() + " is missing, but this data folder held a Tessera job database (" +
                             marker.string() +
                             "): refusing to start an empty farm over its jobs' scenes and images. Restore "
                             "coordinator.db (and coordinator.db-wal if it had one), or delete " +
                             marker.string() + " to start this folder afresh");
  const fs::path wal = fs::path(dir) / "coordinator.db-wal";
  if (text.str().find(kOpen) != std::string::npos && !fs::exists(wal))
    throw std::runtime_error(wal.string() +
                             " is missing, and the coordinator did not close its database cleanly: the latest jobs "
                             "and ends recorded there are lost. Restore it; or, to go on with what coordinator.db "
                             "holds, write \"" +
                             std::string(kClosed) + "\" into " + marker.string());
}

void set_data_marker(const std::string& dir, bool open) {
  write_file_atomic((fs::path(dir) / kMarker).string(),
                    std::string("This folder holds a Tessera coordinator's data (docs/architecture.md).\n") +
                        (open ? kOpen : kClosed) + "\n");
}

}  // namespace tessera
