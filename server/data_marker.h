// The data folder's marker, DATA-FOLDER: written with the job database, so that a database
// that later disappears is noticed instead of an empty farm starting over the folder (and,
// with no job using them, deleting its live scene bundles). It also says whether the
// database was closed cleanly: after an unclean stop SQLite's write-ahead log
// (coordinator.db-wal) holds the latest commits, and a missing one means they are lost.
#pragma once

#include <stdexcept>
#include <string>

namespace tessera {

// Before the database in `dir` is opened: throws std::runtime_error, naming the file and
// what to do, if the marker exists but coordinator.db does not, or if the marker says the
// database was left open and its write-ahead log is gone.
void check_data_marker(const std::string& dir);
// Records the database as open (after opening it) or closed (after a clean close).
void set_data_marker(const std::string& dir, bool open);

// A file of the data folder that exists but cannot be read (its permissions, an I/O error):
// not taken for missing or damaged (a job started over, or failed for good, and its
// checkpoint was overwritten), but an error that stops the start, naming the file and why.
class DataFolderError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One coordinator a data folder: an exclusive lock on DIR/coordinator.lock (flock), held
// while it lives and let go by the kernel if the process dies. Two coordinators on one
// folder each took up every job, wrote the same checkpoints and images, and each start's
// clean-up removed the other's uploads. Throws std::runtime_error naming the folder and the
// process that holds it.
class DataFolderLock {
 public:
  explicit DataFolderLock(const std::string& dir);
  ~DataFolderLock();
  DataFolderLock(const DataFolderLock&) = delete;
  DataFolderLock& operator=(const DataFolderLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace tessera
