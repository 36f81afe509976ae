// Where a job's images go: a seam, so that coordinator tests need no disk.
#pragma once

#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "core/io/image_io.h"
#include "core/render/film.h"

namespace tessera {

// What an image holds besides its colour: AOV layers (aov.h's bits), and whether it is
// denoised as it is committed (a --denoise job's final image: core/denoise/denoise_exr.h).
struct ImageLayers {
  uint32_t aovs = 0;
  bool denoise = false;
};

class ImageSink {
 public:
  // A new image being written band by band (rows top to bottom); commit() replaces the
  // job's last image with it. Destroyed before commit(), it leaves the last image as it was.
  class Writer {
   public:
    virtual ~Writer() = default;
    // `aovs`: the rows' AOV sums, for an image begun with AOV bits (else null); `odd`: the
    // rows of the film's second plane, for one with half-buffers (else null).
    virtual void write_rows(const PixelSums* sums, int rows, const AovSums* aovs, const PixelSums* odd) = 0;
    virtual void commit() = 0;
  };
  virtual ~ImageSink() = default;
  // Slow (encoding, disk): the coordinator calls it, and the writer, without holding its
  // lock. Throws std::runtime_error on failure.
  // The image's pixels are `window` of the whole image `frame` (image coordinates, row 0
  // at the top): a -p job's crop keeps its place (ExrWriter).
  virtual std::unique_ptr<Writer> begin(const std::string& job, const Rect& window, const Rect& frame,
                                        const ImageMetadata& meta, ImageLayers layers) = 0;
  // The last image written, to stream: read from one open file (a newer write replaces the
  // file by rename, so a reader keeps the version it opened), with its size and a version
  // naming that file.
  class Reader {
   public:
    virtual ~Reader() = default;
    virtual uint64_t size() const = 0;
    virtual const std::string& version() const = 0;
    // Up to n bytes from `offset`; 0 at the end. Throws std::runtime_error.
    virtual size_t read(uint64_t offset, char* out, size_t n) = 0;
  };
  // Null when none was written (or the sink keeps no files).
  virtual std::unique_ptr<Reader> open(const std::string& job) const = 0;
  // Whether the job's image file decodes whole (checked before a final image is served:
  // a truncated or damaged file is an error, never a download that exits 0).
  virtual bool intact(const std::string& /*job*/) const { return true; }
  // Makes the job's image file's bytes durable (fsync; its folder is synced by the next
  // durable write there). Throws std::runtime_error.
  virtual void sync(const std::string& /*job*/) {}
  // The string attributes of the job's image file by name (its header alone); none where
  // there is no file (or the sink keeps no files).
  virtual std::map<std::string, std::string> attributes(const std::string& /*job*/) const { return {}; }
  // The last image written, as EXR bytes and a PNG preview; empty if none was written.
  virtual std::string exr(const std::string& job) const = 0;
  virtual std::string png(const std::string& job) const = 0;
  // The job's images are gone (a deleted job); returns the bytes freed. Throws
  // std::runtime_error when they cannot be removed.
  virtual uint64_t remove(const std::string& job) = 0;
  // Removes every job's folder that `known` says no longer names a job (what a crash in the
  // middle of a delete left, after its record was gone).
  virtual void remove_unknown(const std::function<bool(const std::string& job)>&) {}
};

// <dir>/<job>/image.exr, written band by band to a temporary file and renamed into place,
// ZIP-compressed as tessera render's are (core/io/exr_writer.h: the same pixels). The sRGB
// PNG preview is made from that file when somebody asks for it (the live page, a client
// writing .png), and kept until the next write.
class DiskImageSink : public ImageSink {
 public:
  explicit DiskImageSink(std::string dir) : dir_(std::move(dir)) {}
  // A denoised image is written noisy beside it first (image.noisy.exr), then denoised
  // into place: a reader sees the last image or the denoised one, never the noisy one.
  std::unique_ptr<Writer> begin(const std::string& job, const Rect& window, const Rect& frame,
                                const ImageMetadata& meta, ImageLayers layers) override;
  std::string exr(const std::string& job) const override;
  std::string png(const std::string& job) const override;
  std::unique_ptr<Reader> open(const std::string& job) const override;
  // Decodes the file once per version (inode, size, time) and remembers the answer.
  bool intact(const std::string& job) const override;
  std::map<std::string, std::string> attributes(const std::string& job) const override;
  void sync(const std::string& job) override;
  // The job's whole folder (<dir>/<job>/: its image, preview and checkpoint).
  uint64_t remove(const std::string& job) override;
  void remove_unknown(const std::function<bool(const std::string& job)>& known) override;
  std::string path(const std::string& job, const char* file) const;

 private:
  void forget_preview(const std::string& job);
  static constexpr size_t kPreviewsKept = 8;
  std::string dir_;
  mutable std::mutex mu_;  // guards previews_
  // (job, its preview PNG) for the last jobs asked; most recent last. A write drops the job's.
  mutable std::list<std::pair<std::string, std::string>> previews_;
  mutable std::list<std::string> intact_;  // versions found whole, most recent last (guarded by mu_)
};

// Keeps the films in memory, unencoded: for tests, which compare them bit for bit.
class MemoryImageSink : public ImageSink {
 public:
  // Collects the rows; commit() hands the film to write(film).
  std::unique_ptr<Writer> begin(const std::string& job, const Rect& window, const Rect& frame,
                                const ImageMetadata& meta, ImageLayers layers) override;
  // Keeps the film (tests override it to fail).
  virtual void write(const std::string& job, const Film& film, const ImageMetadata& meta);
  std::string exr(const std::string&) const override { return {}; }
  std::string png(const std::string&) const override { return {}; }
  std::unique_ptr<Reader> open(const std::string&) const override { return nullptr; }
  uint64_t remove(const std::string& job) override;
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
