#include "server/image_sink.h"

#include <filesystem>

#include "core/io/files.h"

namespace tessera {

namespace fs = std::filesystem;

std::string DiskImageSink::path(const std::string& job, const char* file) const {
  return (fs::path(dir_) / job / file).string();
}

void DiskImageSink::write(const std::string& job, const Film& film, const ImageMetadata& meta) {
  fs::create_directories(fs::path(dir_) / job);
  write_exr(path(job, "image.exr"), film, meta, true);
  write_png(path(job, "preview.png"), film, true);
}

namespace {
// Images are replaced by rename, never removed: present means whole.
std::string read_if_present(const std::string& p) {
  std::error_code ec;
  return fs::exists(p, ec) ? read_file_bytes(p) : std::string();
}
}  // namespace

std::string DiskImageSink::exr(const std::string& job) const { return read_if_present(path(job, "image.exr")); }
std::string DiskImageSink::png(const std::string& job) const { return read_if_present(path(job, "preview.png")); }

void MemoryImageSink::write(const std::string& job, const Film& film, const ImageMetadata& meta) {
  std::lock_guard<std::mutex> lock(mu_);
  Entry& e = images_[job];
  e.film = film;
  e.meta = meta;
  ++e.writes;
}

Film MemoryImageSink::film(const std::string& job) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = images_.find(job);
  return it == images_.end() ? Film(Rect{}) : it->second.film;
}

ImageMetadata MemoryImageSink::metadata(const std::string& job) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = images_.find(job);
  return it == images_.end() ? ImageMetadata{} : it->second.meta;
}

int MemoryImageSink::writes(const std::string& job) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = images_.find(job);
  return it == images_.end() ? 0 : it->second.writes;
}

}  // namespace tessera
