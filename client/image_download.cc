#include "client/image_download.h"

#include <algorithm>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/io/preview.h"
#define XXH_INLINE_ALL  // header only: nothing to link
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"  // (GCC 12's false positive in xxhash's streaming code)
#include <xxhash.h>
#pragma GCC diagnostic pop

namespace tessera {

namespace fs = std::filesystem;

namespace {

// The download's temporary file and the hash of what it holds.
struct Part {
  explicit Part(const std::string& path) : file(path), hash(XXH64_createState()) { XXH64_reset(hash, 0); }
  ~Part() { XXH64_freeState(hash); }
  AtomicFile file;
  XXH64_state_t* hash;
};

}  // namespace

ImageDownload download_image(const v1::FetchImageRequest& request, const std::vector<std::string>& paths,
                             bool need_final,
                             const std::function<std::unique_ptr<grpc::ClientReaderInterface<v1::ImageChunk>>(
                                 grpc::ClientContext*, const v1::FetchImageRequest&)>& stream,
                             const std::function<std::unique_ptr<grpc::ClientContext>()>& context,
                             const std::function<bool(const grpc::Status&, bool progressed)>& retry) {
  if (paths.empty()) throw std::runtime_error("no output to write the image to");
  for (const std::string& p : paths) make_parent_folder(p);  // (a frame's: out/####/a.exr)
  // Staged beside the first EXR output (renamed into its place: one folder, one file
  // system), else beside the first output; removed whatever happens.
  const auto first_exr = std::find_if(paths.begin(), paths.end(), is_exr_path);
  const std::string download = temporary_path(first_exr != paths.end() ? *first_exr : paths[0], ".download.exr");
  struct Staged {
    const std::string& path;
    ~Staged() {
      std::error_code ec;
      fs::remove(path, ec);
    }
  } staged{download};
  const RemoveOnInterrupt interrupted{download};  // (Ctrl-C: destructors do not run)
  std::unique_ptr<Part> part;                     // (not an optional: g++ 12 warns falsely of its destructor)
  v1::FetchImageRequest req = request;
  ImageDownload got;
  std::string version;
  int damaged = 0;
  for (;;) {
    const std::unique_ptr<grpc::ClientContext> ctx = context();
    auto reader = stream(ctx.get(), req);
    v1::ImageChunk c;
    bool first = true, done = false, restart = false, progressed = false;
    while (reader->Read(&c)) {
      if (first) {
        first = false;
        if (!c.resumed() || !part) {  // from the start: another version, or nothing yet
          part.reset();
          part = std::make_unique<Part>(download);
        }
        version = c.version();
        got.final = c.final();
        got.frame_passes_done = c.frame_passes_done();
        got.bytes = c.size();
        if (need_final && !got.final) {
          ctx->TryCancel();
          break;
        }
      }
      if (done) throw std::runtime_error("the image stream went on past its last piece");
      if (c.offset() != part->file.size()) throw std::runtime_error("the image came out of order");
      if (c.data().size() > got.bytes - part->file.size())
        throw std::runtime_error("the image came longer than its size, " + std::to_string(got.bytes) + " bytes");
      part->file.append(c.data());
      XXH64_update(part->hash, c.data().data(), c.data().size());
      progressed = progressed || !c.data().empty();
      if (!c.last()) continue;
      if (part->file.size() != got.bytes || XXH64_digest(part->hash) != c.xxh64()) {
        if (++damaged > 2) throw std::runtime_error("the image arrived damaged three times (checksum mismatch)");
        part.reset();  // damaged in transit: once more from the start
        req.set_offset(0);
        req.clear_version();
        restart = true;
        break;
      }
      done = true;
    }
    const grpc::Status st = reader->Finish();
    if (need_final && !first && !got.final) return got;  // not final: nothing written
    if (done) break;
    if (restart) continue;
    if (!retry(st, progressed)) throw std::runtime_error(st.ok() ? "the image stream ended early" : st.error_message());
    if (part) {  // resume where it was cut
      req.set_offset(part->file.size());
      req.set_version(version);
    }
  }
  part->file.commit();
  part.reset();
  // Each output: the EXR as it came (the download itself goes into the first EXR's place),
  // a PNG made from it here, from its R, G and B alone.
  // Files are copied a piece at a time and the PNG written as it is encoded: an 8K image
  // never whole in memory.
  std::string at = download;       // where the EXR is
  std::optional<std::string> png;  // the first PNG written
  for (const std::string& p : paths) {
    if (is_exr_path(p)) {
      std::error_code ec;
      if (at == download && (fs::rename(download, p, ec), !ec)) {
        at = p;
      } else {
        copy_file_atomic(at, p);
      }
      continue;
    }
    if (png) {
      copy_file_atomic(*png, p);
    } else {
      write_full_png(at, p);
      png = p;
    }
  }
  return got;
}
}  // namespace tessera
