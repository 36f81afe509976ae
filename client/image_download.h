// An image fetched from the coordinator in pieces (FetchImageChunks), so no message limit
// bounds a frame: written to a temporary file as it comes, resumed where it was cut after a
// lost connection (against the same version of the image; another version starts over),
// checked against the whole file's xxh64, then given to each output: the EXR as it is, a
// PNG made from it here (the coordinator makes no full-size PNG).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "tessera.grpc.pb.h"

namespace tessera {

struct ImageDownload {
  bool final = false;  // the job had ended durably: the image holds its whole film
  uint32_t frame_passes_done = 0;
  uint64_t bytes = 0;
};

// Fetches `request`'s image into `paths` (.exr or .png, each written atomically). With
// `need_final`, an image that is not final is written nowhere (the result says so).
// `stream` makes the call: a fresh context each time. `retry` is asked after a failed
// call whether to go on, and told whether that call brought any of the image (it waits
// and says true, or says false to give up: the error is then thrown as
// std::runtime_error with the call's message). The outputs' folders are made; nothing of
// the download is left on disk when it fails.
ImageDownload download_image(const v1::FetchImageRequest& request, const std::vector<std::string>& paths,
                             bool need_final,
                             const std::function<std::unique_ptr<grpc::ClientReaderInterface<v1::ImageChunk>>(
                                 grpc::ClientContext*, const v1::FetchImageRequest&)>& stream,
                             const std::function<std::unique_ptr<grpc::ClientContext>()>& context,
                             const std::function<bool(const grpc::Status&, bool progressed)>& retry);

}  // namespace tessera
