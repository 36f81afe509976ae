// An image file sent in pieces: whole from the start, resumed at an offset of the same
// version, from the start for another version; the whole file's xxh64 in the last piece.
#include "server/image_stream.h"

#include <gtest/gtest.h>

#define XXH_INLINE_ALL
#include <xxhash.h>

namespace tessera {
namespace {

class StringReader : public ImageSink::Reader {
 public:
  StringReader(std::string bytes, std::string version) : bytes_(std::move(bytes)), version_(std::move(version)) {}
  uint64_t size() const override { return bytes_.size(); }
  const std::string& version() const override { return version_; }
  size_t read(uint64_t offset, char* out, size_t n) override {
    const size_t k = offset >= bytes_.size() ? 0 : std::min(n, bytes_.size() - size_t(offset));
    std::copy_n(bytes_.data() + offset, k, out);
    return k;
  }

 private:
  std::string bytes_, version_;
};

std::vector<v1::ImageChunk> send(StringReader& file, uint64_t offset, const std::string& version, size_t chunk) {
  v1::FetchImageRequest req;
  req.set_offset(offset);
  req.set_version(version);
  std::vector<v1::ImageChunk> out;
  stream_image(file, req, {7, true}, chunk, [&](const v1::ImageChunk& c) {
    out.push_back(c);
    return true;
  });
  return out;
}

std::string joined(const std::vector<v1::ImageChunk>& chunks) {
  std::string s;
  for (const v1::ImageChunk& c : chunks) {
    EXPECT_EQ(c.offset(), chunks.front().offset() + s.size());
    s += c.data();
  }
  return s;
}

const std::string kBytes = [] {
  std::string s;
  for (int i = 0; i < 1000; ++i) s += char(i * 37 % 251);
  return s;
}();

TEST(ImageStream, AWholeFileInPiecesWithItsChecksumLast) {
  StringReader file(kBytes, "v1");
  const auto chunks = send(file, 0, "", 64);
  ASSERT_EQ(chunks.size(), 16u);  // 15 of 64 bytes and one of 40
  EXPECT_EQ(joined(chunks), kBytes);
  EXPECT_EQ(chunks.front().size(), kBytes.size());
  EXPECT_EQ(chunks.front().version(), "v1");
  EXPECT_EQ(chunks.front().frame_passes_done(), 7u);
  EXPECT_TRUE(chunks.front().final());
  EXPECT_FALSE(chunks.front().resumed());
  for (size_t i = 0; i + 1 < chunks.size(); ++i) EXPECT_FALSE(chunks[i].last());
  EXPECT_TRUE(chunks.back().last());
  EXPECT_EQ(chunks.back().xxh64(), XXH64(kBytes.data(), kBytes.size(), 0));
}

TEST(ImageStream, AResumeOfTheSameVersionSendsOnlyWhatIsMissing) {
  StringReader file(kBytes, "v1");
  for (const uint64_t at : {1ull, 63ull, 64ull, 65ull, 999ull, 1000ull}) {
    const auto chunks = send(file, at, "v1", 64);
    ASSERT_FALSE(chunks.empty()) << at;
    EXPECT_TRUE(chunks.front().resumed());
    EXPECT_EQ(chunks.front().offset(), at);
    EXPECT_EQ(joined(chunks), kBytes.substr(at)) << at;
    EXPECT_EQ(chunks.back().xxh64(), XXH64(kBytes.data(), kBytes.size(), 0)) << "the whole file's, at " << at;
  }
}

TEST(ImageStream, AnotherVersionOrAnOffsetPastTheEndStartsOver) {
  StringReader file(kBytes, "v2");
  for (const auto& [at, version] : {std::pair{100ull, "v1"}, std::pair{5000ull, "v2"}}) {
    const auto chunks = send(file, at, version, 300);
    EXPECT_FALSE(chunks.front().resumed());
    EXPECT_EQ(chunks.front().offset(), 0u);
    EXPECT_EQ(joined(chunks), kBytes);
  }
}

TEST(ImageStream, AnEmptyFileIsOneLastPiece) {
  StringReader file("", "v");
  const auto chunks = send(file, 0, "", 64);
  ASSERT_EQ(chunks.size(), 1u);
  EXPECT_TRUE(chunks[0].last());
  EXPECT_EQ(chunks[0].size(), 0u);
}

TEST(ImageStream, AClientGoneStopsTheStream) {
  StringReader file(kBytes, "v1");
  v1::FetchImageRequest req;
  int sent = 0;
  stream_image(file, req, {}, 64, [&](const v1::ImageChunk&) { return ++sent < 3; });
  EXPECT_EQ(sent, 3);
}

}  // namespace
}  // namespace tessera
