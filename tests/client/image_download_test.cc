// An image downloaded in pieces (client/image_download.h), over canned streams: a stream
// cut midway is resumed where it was cut, a damaged download is fetched again, a PNG is
// made from the EXR here, and an image that is not final is written nowhere when the job
// was told to have ended.
#include "client/image_download.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <csignal>
#include <cstring>
#include <filesystem>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/io/interrupt_cleanup.h"
#include "core/io/preview.h"
#define XXH_INLINE_ALL
#include <xxhash.h>

namespace tessera {
namespace {

namespace fs = std::filesystem;

// Pieces, then the stream ends with `status` (a cut connection: UNAVAILABLE).
class Canned : public grpc::ClientReaderInterface<v1::ImageChunk> {
 public:
  Canned(std::vector<v1::ImageChunk> chunks, grpc::Status status) : chunks_(std::move(chunks)), status_(status) {}
  bool Read(v1::ImageChunk* out) override {
    if (next_ == chunks_.size()) return false;
    *out = chunks_[next_++];
    return true;
  }
  grpc::Status Finish() override { return status_; }
  bool NextMessageSize(uint32_t* size) override {
    *size = 1 << 20;
    return next_ < chunks_.size();
  }
  void WaitForInitialMetadata() override {}

 private:
  std::vector<v1::ImageChunk> chunks_;
  grpc::Status status_;
  size_t next_ = 0;
};

class ImageDownloadTest : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_download_" + std::to_string(::getpid()));
  std::string exr;  // a real EXR's bytes
  std::vector<v1::FetchImageRequest> requests;
  // Answers, one per call: (first byte, last byte + 1, how the stream ends, flip a byte?)
  struct Answer {
    size_t from, to;
    grpc::Status end = grpc::Status::OK;
    bool damage = false;
    bool final = true;
    uint64_t size = 0;       // the size the stream declares (0: the image's)
    bool past_last = false;  // a piece more after the last
  };
  std::vector<bool> progressed;  // what each retry was told
  std::function<void()> on_retry;
  std::vector<Answer> answers;

  void SetUp() override {
    fs::create_directories(dir);
    Film film(Rect{0, 0, 23, 17});
    for (int y = 0; y < 17; ++y)
      for (int x = 0; x < 23; ++x) film.at(x, y) = PixelSums{0.1 * x, 0.05 * y, 0.3, 0.01, 1};
    write_exr((dir / "source.exr").string(), film, {});
    exr = read_file_bytes((dir / "source.exr").string());
  }
  void TearDown() override { fs::remove_all(dir); }

  ImageDownload download(const std::vector<std::string>& paths, bool need_final, int* retries) {
    size_t call = 0;
    return download_image(
        v1::FetchImageRequest(), paths, need_final,
        [&](grpc::ClientContext*, const v1::FetchImageRequest& r) {
          requests.push_back(r);
          const Answer a = answers.at(call++);
          std::vector<v1::ImageChunk> chunks;
          for (size_t at = a.from; at < a.to; at += 100) {
            v1::ImageChunk c;
            c.set_offset(at);
            std::string data = exr.substr(at, std::min<size_t>(100, a.to - at));
            if (a.damage && at == a.from) data[0] ^= 1;
            c.set_data(data);
            if (at == a.from) {
              c.set_size(a.size ? a.size : exr.size());
              c.set_version("v1");
              c.set_final(a.final);
              c.set_resumed(a.from > 0);
            }
            if (at + 100 >= exr.size()) {
              c.set_last(true);
              c.set_xxh64(XXH64(exr.data(), exr.size(), 0));
            }
            chunks.push_back(c);
          }
          if (a.past_last) chunks.push_back(chunks.back());
          return std::make_unique<Canned>(chunks, a.end);
        },
        [] { return std::make_unique<grpc::ClientContext>(); },
        [&](const grpc::Status& st, bool came) {
          ++*retries;
          progressed.push_back(came);
          if (on_retry) on_retry();
          return st.error_code() == grpc::StatusCode::UNAVAILABLE;
        });
  }
};

TEST_F(ImageDownloadTest, ACutStreamIsResumedWhereItWasCut) {
  const grpc::Status cut(grpc::StatusCode::UNAVAILABLE, "connection reset");
  answers = {{0, 300, cut}, {300, 701, cut}, {701, exr.size()}};
  int retries = 0;
  const std::string out = (dir / "out.exr").string();
  const ImageDownload got = download({out}, false, &retries);
  EXPECT_EQ(retries, 2);
  EXPECT_EQ(progressed, (std::vector<bool>{true, true}));  // (the fetch's window counts from the last piece)
  ASSERT_EQ(requests.size(), 3u);
  EXPECT_EQ(requests[1].offset(), 300u);
  EXPECT_EQ(requests[1].version(), "v1");
  EXPECT_EQ(requests[2].offset(), 701u);
  EXPECT_EQ(read_file_bytes(out), exr);
  EXPECT_EQ(got.bytes, exr.size());
  EXPECT_TRUE(got.final);
  EXPECT_FALSE(fs::exists(out + ".download.exr"));
}

TEST_F(ImageDownloadTest, ADamagedDownloadIsFetchedAgainWhole) {
  answers = {{0, exr.size(), grpc::Status::OK, true}, {0, exr.size()}};
  int retries = 0;
  const std::string out = (dir / "out.exr").string();
  download({out}, false, &retries);
  ASSERT_EQ(requests.size(), 2u);
  EXPECT_EQ(requests[1].offset(), 0u);  // from the start
  EXPECT_EQ(read_file_bytes(out), exr);
}

TEST_F(ImageDownloadTest, AlwaysDamagedIsAnErrorAndWritesNothing) {
  answers = {{0, exr.size(), grpc::Status::OK, true},
             {0, exr.size(), grpc::Status::OK, true},
             {0, exr.size(), grpc::Status::OK, true}};
  int retries = 0;
  const std::string out = (dir / "out.exr").string();
  EXPECT_THROW(download({out}, false, &retries), std::runtime_error);
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(ImageDownloadTest, APngIsMadeFromTheExrAndEveryOutputWritten) {
  answers = {{0, exr.size()}};
  int retries = 0;
  const std::string png = (dir / "a.png").string(), e1 = (dir / "b.exr").string(), e2 = (dir / "c.exr").string();
  download({png, e1, e2}, false, &retries);
  EXPECT_EQ(read_file_bytes(e1), exr);
  EXPECT_EQ(read_file_bytes(e2), exr);
  const ExrImage img = read_exr(e1);
  EXPECT_EQ(read_file_bytes(png), encode_png(img.width, img.height, img.channels.at("R").data(),
                                             img.channels.at("G").data(), img.channels.at("B").data()));
}

// Issue 29's --exposure: the EXR keeps linear values and carries the EV; every PNG made of
// it (the client's, the coordinator's preview) and a local render's PNG show 2^EV times
// the values.
TEST_F(ImageDownloadTest, EveryPngOfAnExrTakesTheExposureItCarries) {
  Film film(Rect{0, 0, 4, 2});
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) film.at(x, y) = PixelSums{0.01 * (x + 1), 0.02, 0.03, 0, 1};
  const ImageMetadata meta{{kExposureAttribute, exposure_text(2)}};
  const std::string e = (dir / "bright.exr").string(), p = (dir / "bright.png").string();
  write_image(e, film, meta);
  write_image(p, film, meta);
  exr = read_file_bytes(e);
  const ExrImage img = read_exr(e);
  EXPECT_FLOAT_EQ(img.channels.at("R")[0], 0.01f);  // linear, as rendered
  EXPECT_FLOAT_EQ(exposure_scale(img.metadata), 4);
  const std::string bright =
      encode_png(4, 2, img.channels.at("R").data(), img.channels.at("G").data(), img.channels.at("B").data(), false, 4);
  EXPECT_NE(bright,
            encode_png(4, 2, img.channels.at("R").data(), img.channels.at("G").data(), img.channels.at("B").data()));
  EXPECT_EQ(read_file_bytes(p), bright);  // tessera render's PNG
  answers = {{0, exr.size()}};
  int retries = 0;
  const std::string got = (dir / "got.png").string();
  download({got}, false, &retries);
  EXPECT_EQ(read_file_bytes(got), bright);  // the farm client's PNG
  const std::string preview = preview_png(e);
  EXPECT_EQ(preview, encode_png(4, 2, img.channels.at("R").data(), img.channels.at("G").data(),
                                img.channels.at("B").data(), true, 4));  // the coordinator's preview
  // A value that is no EV is ignored, not trusted.
  EXPECT_EQ(exposure_scale({{kExposureAttribute, "bright"}}), 1);
  EXPECT_EQ(exposure_scale({{kExposureFileAttribute, "1e9"}}), 1);
  EXPECT_EQ(exposure_scale({}), 1);
}

TEST_F(ImageDownloadTest, AnImageThatIsNotFinalIsWrittenNowhereWhenOneIsNeeded) {
  Answer a{0, exr.size()};
  a.final = false;
  answers = {a};
  int retries = 0;
  const std::string out = (dir / "out.exr").string();
  const ImageDownload got = download({out}, true, &retries);
  EXPECT_FALSE(got.final);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(out + ".download.exr"));
}

TEST_F(ImageDownloadTest, AFinalErrorIsThrownWithItsMessage) {
  answers = {{0, 0, grpc::Status(grpc::StatusCode::NOT_FOUND, "no job 'x'")}};
  int retries = 0;
  try {
    download({(dir / "out.exr").string()}, false, &retries);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "no job 'x'");
  }
}

// Found by audit: the outputs' folders were made only where their names held no '#' (a
// sequence's out/####/ never was, so no frame was written); the download was staged beside
// the first output and renamed into the first EXR's place (across file systems: EXDEV);
// and it was left on disk when anything after it failed.
TEST_F(ImageDownloadTest, FoldersAreMadeAndNothingOfAFailedDownloadIsLeft) {
  answers = {{0, exr.size()}};
  int retries = 0;
  const std::string png = (dir / "frames" / "0007" / "a.png").string(),
                    e = (dir / "take#1" / "deep" / "a.exr").string();
  download({png, e}, false, &retries);
  EXPECT_EQ(read_file_bytes(e), exr);
  EXPECT_EQ(read_file_bytes(png), full_png(e));
  EXPECT_FALSE(fs::exists(png + ".download.exr"));
  EXPECT_FALSE(fs::exists(e + ".download.exr"));
  // A PNG that cannot be written (a folder in its place): the error, and no download left.
  answers = {{0, exr.size()}};
  const std::string blocked = (dir / "blocked.png").string(), e2 = (dir / "b.exr").string();
  fs::create_directories(blocked);
  EXPECT_THROW(download({e2, blocked}, false, &retries), std::runtime_error);
  for (const auto& f : fs::directory_iterator(dir))
    EXPECT_EQ(f.path().string().find(".download.exr"), std::string::npos) << f.path();
}

// A stream that says more than it declared, or goes on after its last piece, is refused
// (pieces after the last were appended to a checked file; a second "last" left nothing to
// commit, then committed it).
TEST_F(ImageDownloadTest, AStreamLongerThanItsSizeOrPastItsLastPieceIsRefused) {
  int retries = 0;
  const std::string out = (dir / "out.exr").string();
  Answer longer{0, exr.size()};
  longer.size = 200;
  answers = {longer};
  try {
    download({out}, false, &retries);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "the image came longer than its size, 200 bytes");
  }
  Answer past{0, exr.size()};
  past.past_last = true;
  answers = {past};
  requests.clear();
  try {
    download({out}, false, &retries);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "the image stream went on past its last piece");
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(out + ".download.exr"));
}

// The client's PNG reads the EXR's R, G and B only (an 8K EXR with AOV layers was loaded
// whole, and one past 2^26 pixels not at all): the same bytes as encode_png of it whole.
TEST_F(ImageDownloadTest, TheFullSizePngIsEncodePngOfTheExrsColour) {
  const std::string e = (dir / "source.exr").string();
  const ExrImage img = read_exr(e);
  EXPECT_EQ(full_png(e), encode_png(img));
}

// Found by audit: a bit flipped in an EXR's header widened its data window to 4194320 (the
// blocks still decoded): the coordinator allocated a gigabyte to check the file, found it
// intact and served it. A window no image of ours has is refused from the header.
TEST_F(ImageDownloadTest, AnExrWhoseHeaderWasDamagedIsNotIntact) {
  const std::string e = (dir / "source.exr").string();
  std::string why;
  EXPECT_TRUE(exr_intact(e, &why)) << why;
  std::string bytes = read_file_bytes(e);
  const std::string key("dataWindow\0box2i\0", 17);
  const size_t at = bytes.find(key);
  ASSERT_NE(at, std::string::npos);
  const size_t max_x = at + key.size() + 4 + 8;  // (its size, then xmin, ymin, xmax, ymax)
  const int32_t wide = (1 << 22) + 15;
  std::memcpy(&bytes[max_x], &wide, 4);
  const std::string damaged = (dir / "damaged.exr").string();
  write_file_atomic(damaged, bytes);
  EXPECT_FALSE(exr_intact(damaged, &why));
  EXPECT_NE(why.find("is no image Tessera writes"), std::string::npos) << why;
  EXPECT_THROW(full_png(damaged), std::runtime_error);
  EXPECT_THROW(preview_png(damaged), std::runtime_error);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Ctrl-C while the download waits to resume: destructors do not run, the client's cleanup
// removes the half-downloaded file (it was left beside the output, one per interrupted fetch).
TEST_F(ImageDownloadTest, CtrlCMidwayLeavesNoHalfDownloadedFile) {
  const std::string out = (dir / "out.exr").string();
  const std::string part = out + ".download.exr.tmp";
  const auto interrupted = [&] {
    install_interrupt_cleanup();
    answers = {{0, 300, grpc::Status(grpc::StatusCode::UNAVAILABLE, "connection reset")}};
    on_retry = [&] {
      if (!fs::exists(part)) std::_Exit(3);  // (the test would prove nothing)
      std::raise(SIGINT);
    };
    int retries = 0;
    download({out}, false, &retries);
  };
  EXPECT_EXIT(interrupted(), ::testing::KilledBySignal(SIGINT), "");
  EXPECT_FALSE(fs::exists(part));
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace tessera
