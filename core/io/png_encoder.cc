#include "core/io/png_encoder.h"

#include <png.h>

#include <csetjmp>
#include <stdexcept>

#include "core/io/image_io.h"  // srgb_byte

namespace tessera {

// libpng reports errors by longjmp to the last setjmp (png_jmpbuf): each call into it is
// guarded in a frame of its own that holds no object with a destructor, and turned into an
// exception there, after the jump.
struct PngEncoder::State {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::string out;
  PngEncoder::Sink sink;
  char error[256] = "";
  int width = 0, height = 0, rows = 0;
  std::vector<uint8_t> row;
};

namespace {

void on_error(png_structp png, png_const_charp message) {
  auto* s = static_cast<PngEncoder::State*>(png_get_error_ptr(png));
  std::snprintf(s->error, sizeof s->error, "%s", message);
  png_longjmp(png, 1);
}

void on_warning(png_structp, png_const_charp) {}

void on_write(png_structp png, png_bytep data, png_size_t size) {
  auto* s = static_cast<PngEncoder::State*>(png_get_io_ptr(png));
  bool failed = false;  // (set in a handler, jumped from after it: no longjmp out of a catch)
  try {
    if (s->sink)
      s->sink(reinterpret_cast<const char*>(data), size);
    else
      s->out.append(reinterpret_cast<const char*>(data), size);
  } catch (const std::exception& e) {
    std::snprintf(s->error, sizeof s->error, "%s", e.what());
    failed = true;
  } catch (...) {
    std::snprintf(s->error, sizeof s->error, "%s", "its bytes could not be kept");
    failed = true;
  }
  if (failed) png_longjmp(png, 1);  // (the message is the sink's)
}

void on_flush(png_structp) {}

[[noreturn]] void fail(const PngEncoder::State& s) {
  throw std::runtime_error(std::string("cannot encode PNG: ") + (s.error[0] ? s.error : "libpng failed"));
}

// Each returns false where libpng jumped out (its message in s->error).
bool start(PngEncoder::State* s, int level) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_set_write_fn(s->png, s, on_write, on_flush);
  png_set_IHDR(s->png, s->info, png_uint_32(s->width), png_uint_32(s->height), 8, PNG_COLOR_TYPE_RGB,
               PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(s->png, level);
  png_write_info(s->png, s->info);
  return true;
}

bool put_row(PngEncoder::State* s) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_write_row(s->png, s->row.data());
  return true;
}

bool end(PngEncoder::State* s) {
  if (setjmp(png_jmpbuf(s->png))) return false;
  png_write_end(s->png, s->info);
  return true;
}

}  // namespace

PngEncoder::PngEncoder(int width, int height, bool fast, Sink sink) : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.sink = std::move(sink);
  // PNG's limit is 2^31 - 1 a side; libpng's default user limit is 10^6.
  if (width < 1 || height < 1 || width > 1000000 || height > 1000000)
    throw std::runtime_error("cannot encode PNG: " + std::to_string(width) + " x " + std::to_string(height) +
                             " is no PNG size");
  s.width = width;
  s.height = height;
  s.row.resize(size_t(width) * 3);
  s.png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &s, on_error, on_warning);
  if (s.png) s.info = png_create_info_struct(s.png);
  if (!s.png || !s.info) {
    png_destroy_write_struct(&s.png, &s.info);
    throw std::runtime_error("cannot encode PNG: libpng could not start");
  }
  if (!start(&s, fast ? 1 : 6)) fail(s);
}

PngEncoder::~PngEncoder() { png_destroy_write_struct(&state_->png, &state_->info); }

void PngEncoder::write_row(const float* r, const float* g, const float* b, float scale) {
  State& s = *state_;
  if (s.rows >= s.height) throw std::runtime_error("cannot encode PNG: more rows than its height");
  for (int x = 0; x < s.width; ++x) {
    s.row[3 * size_t(x)] = srgb_byte(r[x] * scale);
    s.row[3 * size_t(x) + 1] = srgb_byte(g[x] * scale);
    s.row[3 * size_t(x) + 2] = srgb_byte(b[x] * scale);
  }
  if (!put_row(&s)) fail(s);
  ++s.rows;
}

std::string PngEncoder::finish() {
  State& s = *state_;
  if (s.rows != s.height) throw std::runtime_error("cannot encode PNG: rows missing");
  if (!end(&s)) fail(s);
  return std::move(s.out);
}

}  // namespace tessera
