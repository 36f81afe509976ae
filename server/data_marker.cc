#include "server/data_marker.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
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

DataFolderLock::DataFolderLock(const std::string& dir) {
  const std::string path = (fs::path(dir) / "coordinator.lock").string();
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw std::runtime_error(path + ": cannot open the data folder's lock: " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char holder[32] = {};
    const ssize_t n = ::pread(fd_, holder, sizeof holder - 1, 0);
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK)
      throw std::runtime_error("data folder " + dir + " is in use by another coordinator" +
                               (n > 0 ? " (process " + std::string(holder, size_t(n)) + ")" : std::string()) +
                               ": one coordinator a data folder (" + path + " is locked)");
    throw std::runtime_error(path + ": cannot lock the data folder: " + std::strerror(err));
  }
  // Who holds it, for the next one's message.
  const std::string pid = std::to_string(::getpid());
  if (::ftruncate(fd_, 0) == 0)
    (void)!::pwrite(fd_, pid.data(), pid.size(), 0);  // (only a message's detail: nothing to do if it fails)
}

DataFolderLock::~DataFolderLock() {
  if (fd_ >= 0) ::close(fd_);  // (the lock goes with the descriptor)
}

}  // namespace tessera
