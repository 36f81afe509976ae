#include "server/image_stream.h"

#include <stdexcept>
#include <vector>

#define XXH_INLINE_ALL  // header only: nothing to link
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"  // (GCC 12's false positive in xxhash's streaming code)
#include <xxhash.h>
#pragma GCC diagnostic pop

namespace tessera {

v1::Image whole_image(const ImageSink& sink, const std::string& job, bool exr, bool png, const ImageStreamHeader& h) {
  v1::Image img;
  if (exr) img.set_exr(sink.exr(job));
  if (png) img.set_png(sink.png(job));
  img.set_frame_passes_done(h.frame_passes_done);
  img.set_final(h.final);
  return img;
}

void stream_image(ImageSink::Reader& file, const v1::FetchImageRequest& req, const ImageStreamHeader& header,
                  size_t chunk_bytes, const std::function<bool(const v1::ImageChunk&)>& write) {
  const uint64_t size = file.size();
  const bool resumed = req.offset() > 0 && req.version() == file.version() && req.offset() <= size;
  const uint64_t start = resumed ? req.offset() : 0;
  XXH64_state_t* hash = XXH64_createState();
  struct Free {
    XXH64_state_t* h;
    ~Free() { XXH64_freeState(h); }
  } free_hash{hash};
  XXH64_reset(hash, 0);
  std::vector<char> buf(std::max<size_t>(1, chunk_bytes));
  uint64_t at = 0;
  bool first = true;
  do {
    const size_t n = size - at < buf.size() ? size_t(size - at) : buf.size();
    const size_t k = n ? file.read(at, buf.data(), n) : 0;
    if (k != n) throw std::runtime_error("the image file was cut short while it was read");
    XXH64_update(hash, buf.data(), k);
    const uint64_t from = at;
    at += k;
    if (at <= start && at < size) continue;  // before a resumed offset: hashed, not sent
    v1::ImageChunk c;
    const uint64_t skip = from < start ? start - from : 0;
    c.set_offset(from + skip);
    c.set_data(buf.data() + skip, k - size_t(skip));
    if (first) {
      c.set_size(size);
      c.set_version(file.version());
      c.set_frame_passes_done(header.frame_passes_done);
      c.set_final(header.final);
      c.set_resumed(resumed);
      first = false;
    }
    if (at == size) {
      c.set_last(true);
      c.set_xxh64(XXH64_digest(hash));
    }
    if (!write(c)) return;
  } while (at < size);
}

}  // namespace tessera
