// The data folder's marker, DATA-FOLDER: written with the job database, so that a database
// that later disappears is noticed instead of an empty farm starting over the folder (and,
// with no job using them, deleting its live scene bundles). It also says whether the
// database was closed cleanly: after an unclean stop SQLite's write-ahead log
// (coordinator.db-wal) holds the latest commits, and a missing one means they are lost.
#pragma once

#include <string>

namespace tessera {

// Before the database in `dir` is opened: throws std::runtime_error, naming the file and
// what to do, if the marker exists but coordinator.db does not, or if the marker says the
// database was left open and its write-ahead log is gone.
void check_data_marker(const std::string& dir);
// Records the database as open (after opening it) or closed (after a clean close).
void set_data_marker(const std::string& dir, bool open);

}  // namespace tessera
