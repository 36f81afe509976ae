// An 8-bit sRGB PNG written a row at a time (libpng): an image of any size costs one row of
// bytes besides its compressed file, where a whole-image writer wanted the image three
// times over (an 8K PNG made from its EXR took 614 MB). Every PNG Tessera writes comes
// from here, so the same pixels give the same bytes whichever path made them.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace tessera {

class PngEncoder {
 public:
  // Where the file's bytes go as they are made (a file: the PNG is never whole in memory);
  // it may throw, and the encoder then throws its message.
  using Sink = std::function<void(const char* data, size_t n)>;
  // `fast`: zlib's fastest level (progressive previews), else its default. Without a
  // `sink` the bytes are kept for finish(). Throws std::runtime_error for a size PNG
  // cannot hold.
  PngEncoder(int width, int height, bool fast, Sink sink = {});
  ~PngEncoder();
  PngEncoder(const PngEncoder&) = delete;
  PngEncoder& operator=(const PngEncoder&) = delete;

  // The next row, top first: linear R, G, B (width values each), each times `scale` and
  // through the sRGB transfer (srgb_byte).
  void write_row(const float* r, const float* g, const float* b, float scale);
  // After every row: the file's bytes (empty where a sink took them).
  std::string finish();

  struct State;  // (libpng's callbacks reach it)

 private:
  std::unique_ptr<State> state_;
};

}  // namespace tessera
