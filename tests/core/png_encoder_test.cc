// Every PNG Tessera writes goes through PngEncoder (libpng, a row at a time): the pixels a
// decoder reads back are srgb_byte of the values, a film's PNG and the PNG made from its
// EXR (a farm's download, a crop in its data window, bands of rows) are the same bytes, and
// misuse is an error, not a broken file.
#include "core/io/png_encoder.h"

#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/io/preview.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

// The decoded RGB bytes (stb_image), with the size.
std::vector<uint8_t> decode(const std::string& png, int* w, int* h) {
  int n = 0;
  std::unique_ptr<uint8_t, void (*)(void*)> data(
      stbi_load_from_memory(reinterpret_cast<const uint8_t*>(png.data()), int(png.size()), w, h, &n, 3),
      stbi_image_free);
  if (!data) return {};
  return std::vector<uint8_t>(data.get(), data.get() + size_t(*w) * size_t(*h) * 3);
}

// A scratch folder per test, removed after it (failed or not), and films to write there.
class PngFiles : public ::testing::Test {
 protected:
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
  std::string path(const char* name) const { return (dir / name).string(); }
  // A film of `window` whose pixel (x, y) holds sums(x, y).
  template <typename F>
  static Film film_of(Rect window, F sums) {
    Film film(window);
    for (int y = 0; y < film.height(); ++y)
      for (int x = 0; x < film.width(); ++x) film.at(x, y) = sums(x, y);
    return film;
  }
  const fs::path dir = fs::temp_directory_path() / ("png_encoder_test_" + std::to_string(::getpid()));
};

TEST(PngEncoder, DecodesToTheSrgbBytesOfTheValues) {
  const int w = 37, h = 23;
  std::vector<float> r(size_t(w) * h), g(r.size()), b(r.size());
  for (size_t i = 0; i < r.size(); ++i) {
    r[i] = float(i % 97) / 50;         // past 1 too (clamped)
    g[i] = float(i % 13) / 13 - 0.1f;  // below 0 too
    b[i] = i % 7 ? 0.25f : NAN;        // NaN: black
  }
  for (const bool fast : {false, true})
    for (const float scale : {1.0f, 4.0f}) {
      const std::string png = encode_png(w, h, r.data(), g.data(), b.data(), fast, scale);
      int dw = 0, dh = 0;
      const std::vector<uint8_t> px = decode(png, &dw, &dh);
      ASSERT_EQ(dw, w);
      ASSERT_EQ(dh, h);
      for (size_t i = 0; i < r.size(); ++i) {
        ASSERT_EQ(px[3 * i], srgb_byte(r[i] * scale)) << i;
        ASSERT_EQ(px[3 * i + 1], srgb_byte(g[i] * scale)) << i;
        ASSERT_EQ(px[3 * i + 2], srgb_byte(b[i] * scale)) << i;
      }
    }
}

// tessera render's PNG of a film and the PNG made from the film's EXR (full_png, as a farm
// download makes it: bands of 64 rows, here 150 rows of a crop placed at (5, 7)) are the
// same bytes.
TEST_F(PngFiles, AFilmsPngAndThePngOfItsExrAreTheSameBytes) {
  const Film film = film_of(Rect{5, 7, 41, 150}, [](int x, int y) {
    return PixelSums{0.01 * x * (y % 5), 0.003 * y, 0.5, 0, uint32_t(1 + (x + y) % 3)};
  });
  const ImageMetadata meta{{kExposureAttribute, exposure_text(1)}};
  const std::string exr = path("a.exr"), png = path("a.png");
  write_image(exr, film, meta, nullptr, 0, Rect{0, 0, 64, 200});
  write_image(png, film, meta);
  EXPECT_EQ(full_png(exr), read_file_bytes(png));
  int w = 0, h = 0;
  EXPECT_EQ(decode(read_file_bytes(png), &w, &h).size(), size_t(41) * 150 * 3);
}

// The PNG written to a file as it is encoded is full_png's bytes; a file that cannot be
// written is an error naming it, and leaves nothing. copy_file_atomic copies a file of
// several of its pieces bit for bit.
TEST_F(PngFiles, APngWrittenAsItIsEncodedIsFullPngsBytes) {
  const Film film = film_of(Rect{0, 0, 300, 200}, [](int x, int y) {
    return PixelSums{double((x * 7919 + y * 104729) % 1000) / 999, 0.25, double(y) / 200, 0, 1};
  });
  const std::string exr = path("a.exr"), png = path("a.png");
  write_exr(exr, film, {});
  write_full_png(exr, png);
  EXPECT_EQ(read_file_bytes(png), full_png(exr));
  const std::string nowhere = path("missing/b.png");
  try {
    write_full_png(exr, nowhere);
    ADD_FAILURE() << "a PNG written into a missing folder";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(nowhere), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir / "missing"));
  // A copy of more than one piece (1 MiB each).
  const std::string big = path("big.bin"), copy = path("copy.bin");
  std::string bytes(2500000, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = char(i * 2654435761u >> 24);
  write_file_atomic(big, bytes);
  copy_file_atomic(big, copy);
  EXPECT_EQ(read_file_bytes(copy), bytes);
  EXPECT_THROW(copy_file_atomic(path("none"), path("c.bin")), std::runtime_error);
  EXPECT_FALSE(fs::exists(dir / "c.bin"));
}

TEST(PngEncoder, MisuseIsAnError) {
  EXPECT_THROW(PngEncoder(0, 4, false), std::runtime_error);
  EXPECT_THROW(PngEncoder(4, -1, false), std::runtime_error);
  const float row[2] = {0.5f, 0.5f};
  PngEncoder short_of_rows(2, 2, false);
  short_of_rows.write_row(row, row, row, 1);
  EXPECT_THROW(short_of_rows.finish(), std::runtime_error);
  PngEncoder too_many(2, 1, true);
  too_many.write_row(row, row, row, 1);
  EXPECT_THROW(too_many.write_row(row, row, row, 1), std::runtime_error);
  EXPECT_NE(too_many.finish().size(), 0u);
  // A sink that cannot take the bytes (a full disk): the encoder's error is its message.
  try {
    PngEncoder failing(2, 1, false, [](const char*, size_t) { throw std::runtime_error("out.png: disk full"); });
    ADD_FAILURE() << "the header went to a failing sink";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("out.png: disk full"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tessera
