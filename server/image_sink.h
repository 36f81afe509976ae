// Where a job's images go: a seam, so that coordinator tests need no disk.
#pragma once

#include <list>
#include <map>
#include <mutex>
#include <string>

#include "core/io/image_io.h"
#include "core/render/film.h"

namespace tessera {

class ImageSink {
 public:
  virtual ~ImageSink() = default;
  // Replaces the job's image with this film. Slow (encoding, disk): the coordinator calls
  // it without holding its lock. Throws std::runtime_error on failure.
  virtual void write(const std::string& job, const Film& film, const ImageMetadata& meta) = 0;
  // The last image written, as EXR and PNG bytes; empty if none was written.
  virtual std::string exr(const std::string& job) const = 0;
  virtual std::string png(const std::string& job) const = 0;
};

// <dir>/<job>/image.exr, written to a temporary file and renamed into place, uncompressed:
// progressive images are frequent, and the final one is on the path between the last tile
// and the client's download. The sRGB PNG preview is made from that file when somebody
// asks for it (the live page, a client writing .png), and kept until the next write.
class DiskImageSink : public ImageSink {
 public:
  explicit DiskImageSink(std::string dir) : dir_(std::move(dir)) {}
  void write(const std::string& job, const Film& film, const ImageMetadata& meta) override;
  std::string exr(const std::string& job) const override;
  std::string png(const std::string& job) const override;
  std::string path(const std::string& job, const char* file) const;

 private:
  void forget_preview(const std::string& job);
  static constexpr size_t kPreviewsKept = 8;
  std::string dir_;
  mutable std::mutex mu_;  // guards previews_
  // (job, its preview PNG) for the last jobs asked; most recent last. A write drops the job's.
  mutable std::list<std::pair<std::string, std::string>> previews_;
};

// Keeps the films in memory, unencoded: for tests, which compare them bit for bit.
class MemoryImageSink : public ImageSink {
 public:
  void write(const std::string& job, const Film& film, const ImageMetadata& meta) override;
  std::string exr(const std::string&) const override { return {}; }
  std::string png(const std::string&) const override { return {}; }
  // The last film written for the job (an empty film if none), and how many were written.
  Film film(const std::string& job) const;
  ImageMetadata metadata(const std::string& job) const;
  int writes(const std::string& job) const;

 private:
  struct Entry {
    Film film{Rect{}};
    ImageMetadata meta;
    int writes = 0;
  };
  mutable std::mutex mu_;
  std::map<std::string, Entry> images_;
};

}  // namespace tessera
