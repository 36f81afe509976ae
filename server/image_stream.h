// An image file sent in pieces (FetchImageChunks): from the request's offset when it names
// the same version (a resumed stream), else from the start; the whole file's xxh64 in the
// last piece (the bytes before a resumed offset are read for it, not sent again).
#pragma once

#include <cstdint>
#include <functional>

#include "server/image_sink.h"
#include "wire.h"

namespace tessera {

struct ImageStreamHeader {
  uint32_t frame_passes_done = 0;
  bool final = false;
};

// Sends the file through `write` in pieces of `chunk_bytes`; stops early when `write`
// returns false (the client went away). Throws std::runtime_error when the file cannot be
// read.
// The image whole (FetchImage: small images), as the sink has it: its files are replaced by
// rename, never changed in place, so this reads them without any lock.
v1::Image whole_image(const ImageSink& sink, const std::string& job, bool exr, bool png, const ImageStreamHeader& h);

void stream_image(ImageSink::Reader& file, const v1::FetchImageRequest& request, const ImageStreamHeader& header,
                  size_t chunk_bytes, const std::function<bool(const v1::ImageChunk&)>& write);

}  // namespace tessera
