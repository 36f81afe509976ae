#include "core/io/files.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace tessera {

std::string read_file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": cannot open file");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

namespace {
void sync_folder_of(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
  if (const int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC); d >= 0) {
    ::fsync(d);
    ::close(d);
  }
}
}  // namespace

namespace {
std::atomic<bool> unique_temporaries{false};
}  // namespace

void use_unique_temporaries(bool on) { unique_temporaries = on; }

std::string temporary_path(const std::string& path, const char* suffix) {
  return unique_temporaries ? path + "." + std::to_string(::getpid()) + suffix : path + suffix;
}

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), tmp_(temporary_path(path_)) {
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) fail("write");
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) {
    ::close(fd_);
    ::unlink(tmp_.c_str());
  }
}

void AtomicFile::fail(const std::string& what) {
  const std::string why = std::strerror(errno);
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  ::unlink(tmp_.c_str());
  throw std::runtime_error(path_ + ": cannot " + what + ": " + why);
}

void AtomicFile::append(const char* data, size_t n) {
  for (size_t at = 0; at < n;) {
    const ssize_t k = ::write(fd_, data + at, n - at);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) fail("write");
    at += size_t(k);
  }
  size_ += n;
}

void copy_file_atomic(const std::string& from, const std::string& to) {
  std::FILE* in = std::fopen(from.c_str(), "rb");
  if (!in) throw std::runtime_error(from + ": cannot read: " + std::strerror(errno));
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> closer(in, std::fclose);
  AtomicFile out(to);
  std::vector<char> buf(size_t(1) << 20);
  for (size_t n; (n = std::fread(buf.data(), 1, buf.size(), in)) > 0;) out.append(buf.data(), n);
  if (std::ferror(in)) throw std::runtime_error(from + ": cannot read: " + std::strerror(errno));
  out.commit();
}

void AtomicFile::commit(const AtomicWrite& how) {
  if (how.durable && ::fsync(fd_) != 0) fail("sync");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) {
    ::unlink(tmp_.c_str());
    throw std::runtime_error(path_ + ": cannot write: " + std::strerror(errno));
  }
  commit_file(tmp_, path_, how);
}

void commit_file(const std::string& tmp, const std::string& path, const AtomicWrite& how) {
  if (how.before_rename) how.before_rename();
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    ::unlink(tmp.c_str());
    throw std::runtime_error(path + ": cannot replace: " + why);
  }
  if (how.durable) sync_folder_of(path);
}

void write_file_atomic(const std::string& path, const std::string& bytes, const AtomicWrite& how) {
  AtomicFile f(path);
  f.append(bytes);
  f.commit(how);
}

uint64_t remove_folder(const std::string& path) {
  namespace fs = std::filesystem;
  uint64_t bytes = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(path, ec); !ec && it != fs::recursive_directory_iterator();
       it.increment(ec))
    if (it->is_regular_file(ec)) bytes += it->file_size(ec);
  fs::remove_all(path, ec);
  if (ec) throw std::runtime_error("cannot remove " + path + ": " + ec.message());
  return bytes;
}

void make_parent_folder(const std::string& path) {
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (dir.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir))
    throw std::runtime_error(path + ": cannot make its folder " + dir.string() + ": " +
                             (ec ? ec.message() : std::string("not a folder")));
}

}  // namespace tessera
