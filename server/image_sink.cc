#include "server/image_sink.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "core/denoise/denoise_exr.h"
#include "core/io/exr_writer.h"
#include "core/io/files.h"
#include "core/io/preview.h"
#include "core/util/log.h"

namespace tessera {

namespace fs = std::filesystem;

std::string DiskImageSink::path(const std::string& job, const char* file) const {
  return (fs::path(dir_) / job / file).string();
}

namespace {
class DiskWriter : public ImageSink::Writer {
 public:
  // `path`: where the image goes; with `denoised` there, the noisy one is written to
  // noisy_path first.
  DiskWriter(std::string path, std::string noisy_path, const Rect& window, const Rect& frame, const ImageMetadata& meta,
             ImageLayers layers, std::function<void()> done)
      : exr_(layers.denoise ? noisy_path : path, window, frame, meta, true, layers.aovs),
        path_(std::move(path)),
        noisy_path_(std::move(noisy_path)),
        denoise_(layers.denoise),
        done_(std::move(done)) {}
  void write_rows(const PixelSums* sums, int rows, const AovSums* aovs, const PixelSums* odd) override {
    exr_.write_rows(sums, rows, aovs, odd);
  }
  void commit() override {
    exr_.commit();
    if (denoise_) {
      const DenoiseReport r = denoise_exr(noisy_path_, path_);
      std::remove(noisy_path_.c_str());
      spdlog::info("{}: denoised {}x{} in {:.2f} s", path_, r.width, r.height, r.seconds);
    }
    done_();
  }

 private:
  ExrWriter exr_;
  std::string path_, noisy_path_;
  bool denoise_;
  std::function<void()> done_;
};

class FilmWriter : public ImageSink::Writer {
 public:
  FilmWriter(int width, int height, std::function<void(const Film&)> done)
      : film_(Rect{0, 0, width, height}), done_(std::move(done)) {}
  void write_rows(const PixelSums* sums, int rows, const AovSums*,
                  const PixelSums*) override {  // (the film alone: tests)
    if (rows <= 0) return;
    std::copy_n(sums, size_t(rows) * size_t(film_.width()), &film_.at(0, next_));
    next_ += rows;
  }
  void commit() override { done_(film_); }

 private:
  Film film_;
  int next_ = 0;
  std::function<void(const Film&)> done_;
};
}  // namespace

std::unique_ptr<ImageSink::Writer> DiskImageSink::begin(const std::string& job, const Rect& window, const Rect& frame,
                                                        const ImageMetadata& meta, ImageLayers layers) {
  fs::create_directories(fs::path(dir_) / job);
  return std::make_unique<DiskWriter>(path(job, "image.exr"), path(job, "image.noisy.exr"), window, frame, meta, layers,
                                      [this, job] { forget_preview(job); });
}

std::unique_ptr<ImageSink::Writer> MemoryImageSink::begin(const std::string& job, const Rect& window, const Rect&,
                                                          const ImageMetadata& meta, ImageLayers) {
  // (the window's pixels at (0, 0), as the tests' films are)
  return std::make_unique<FilmWriter>(window.w, window.h, [this, job, meta](const Film& f) { write(job, f, meta); });
}

void DiskImageSink::forget_preview(const std::string& job) {
  std::lock_guard<std::mutex> lock(mu_);
  previews_.remove_if([&](const auto& p) { return p.first == job; });
}

namespace {
// Images are replaced by rename, never removed: present means whole.
std::string read_if_present(const std::string& p) {
  std::error_code ec;
  return fs::exists(p, ec) ? read_file_bytes(p) : std::string();
}
}  // namespace

std::string DiskImageSink::exr(const std::string& job) const { return read_if_present(path(job, "image.exr")); }
std::string DiskImageSink::png(const std::string& job) const {
  std::lock_guard<std::mutex> lock(mu_);  // one encode at a time: it is the expensive part
  for (auto it = previews_.begin(); it != previews_.end(); ++it)
    if (it->first == job) {
      previews_.splice(previews_.end(), previews_, it);
      return it->second;
    }
  std::error_code ec;
  const std::string exr_path = path(job, "image.exr");
  if (!fs::exists(exr_path, ec)) return {};
  std::string png = preview_png(exr_path);  // a few rows at a time, at most 1280 pixels wide
  previews_.emplace_back(job, png);
  if (previews_.size() > kPreviewsKept) previews_.pop_front();
  return png;
}

namespace {
class FileReader : public ImageSink::Reader {
 public:
  FileReader(int fd, uint64_t size, std::string version) : fd_(fd), size_(size), version_(std::move(version)) {}
  ~FileReader() override { ::close(fd_); }
  uint64_t size() const override { return size_; }
  const std::string& version() const override { return version_; }
  size_t read(uint64_t offset, char* out, size_t n) override {
    for (;;) {
      const ssize_t k = ::pread(fd_, out, n, off_t(offset));
      if (k >= 0) return size_t(k);
      if (errno != EINTR) throw std::runtime_error(std::string("cannot read the image: ") + std::strerror(errno));
    }
  }

 private:
  int fd_;
  uint64_t size_;
  std::string version_;
};
}  // namespace

std::unique_ptr<ImageSink::Reader> DiskImageSink::open(const std::string& job) const {
  const int fd = ::open(path(job, "image.exr").c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return nullptr;
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    return nullptr;
  }
  char version[96];  // the file itself: a rewrite is another inode, size or time
  std::snprintf(version, sizeof version, "%llx.%llx.%llx.%lld.%ld", (unsigned long long)st.st_dev,
                (unsigned long long)st.st_ino, (unsigned long long)st.st_size, (long long)st.st_mtim.tv_sec,
                st.st_mtim.tv_nsec);
  return std::make_unique<FileReader>(fd, uint64_t(st.st_size), version);
}

bool DiskImageSink::intact(const std::string& job) const {
  const std::unique_ptr<Reader> file = open(job);
  if (!file) return false;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (std::find(intact_.begin(), intact_.end(), file->version()) != intact_.end()) return true;
  }
  std::string why;
  if (!exr_intact(path(job, "image.exr"), &why)) {
    spdlog::error("job {}: its image file does not decode: {}", job, why);
    return false;
  }
  std::lock_guard<std::mutex> lock(mu_);
  intact_.push_back(file->version());
  if (intact_.size() > 64) intact_.pop_front();
  return true;
}

void DiskImageSink::sync(const std::string& job) {
  const std::string file = path(job, "image.exr");
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error(file + ": cannot open to sync: " + std::strerror(errno));
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0) throw std::runtime_error(file + ": cannot sync: " + std::strerror(err));
}

std::map<std::string, std::string> DiskImageSink::attributes(const std::string& job) const {
  return exr_string_attributes(path(job, "image.exr"));
}

uint64_t DiskImageSink::remove(const std::string& job) {
  forget_preview(job);
  return remove_folder((fs::path(dir_) / job).string());
}

void DiskImageSink::remove_unknown(const std::function<bool(const std::string& job)>& known) {
  std::error_code ec;
  std::vector<std::string> gone;
  for (const auto& entry : fs::directory_iterator(dir_, ec))
    if (!known(entry.path().filename().string())) gone.push_back(entry.path().filename().string());
  for (const std::string& job : gone) try {
      remove(job);
    } catch (const std::exception&) {  // tried again at the next start
    }
}

uint64_t MemoryImageSink::remove(const std::string& job) {
  std::lock_guard<std::mutex> lock(mu_);
  return images_.erase(job);
}

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
