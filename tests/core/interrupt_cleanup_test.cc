// A process ended by Ctrl-C (or a kill) leaves no half-written file where it installed the
// cleanup (core/io/interrupt_cleanup.h): an AtomicFile's and an EXR writer's temporary
// files are removed, and the process still ends by the signal.
#include "core/io/interrupt_cleanup.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>

#include "core/io/exr_writer.h"
#include "core/io/files.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

class InterruptCleanupTest : public ::testing::Test {
 protected:
  fs::path dir = fs::temp_directory_path() / ("tessera_interrupt_" + std::to_string(::getpid()));
  void SetUp() override { fs::create_directories(dir); }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(InterruptCleanupTest, AHalfWrittenFileIsRemovedAndTheSignalStillEndsTheProcess) {
  const std::string path = (dir / "out.bin").string();
  for (const int sig : {SIGINT, SIGTERM, SIGHUP}) {
    EXPECT_EXIT(
        {
          install_interrupt_cleanup();
          AtomicFile f(path);
          f.append("half of it");
          if (!fs::exists(path + ".tmp")) std::_Exit(3);
          std::raise(sig);
        },
        ::testing::KilledBySignal(sig), "");
    EXPECT_FALSE(fs::exists(path + ".tmp")) << sig;
    EXPECT_FALSE(fs::exists(path)) << sig;
  }
}

TEST_F(InterruptCleanupTest, AnExrBeingWrittenIsRemoved) {
  const std::string path = (dir / "out.exr").string();
  EXPECT_EXIT(
      {
        install_interrupt_cleanup();
        ExrWriter w(path, 8, 4, {}, true, 0);
        if (!fs::exists(path + ".tmp")) std::_Exit(3);
        std::raise(SIGINT);
      },
      ::testing::KilledBySignal(SIGINT), "");
  EXPECT_FALSE(fs::exists(path + ".tmp"));
}

// Files that are done, or released, are not the cleanup's: only those still registered go.
TEST_F(InterruptCleanupTest, OnlyFilesStillBeingWrittenAreRemoved) {
  const std::string done = (dir / "done.bin").string(), kept = (dir / "kept.bin").string();
  EXPECT_EXIT(
      {
        install_interrupt_cleanup();
        write_file_atomic(done, "whole");
        { const RemoveOnInterrupt released{kept}; }
        write_file_atomic(kept, "mine");
        std::raise(SIGINT);
      },
      ::testing::KilledBySignal(SIGINT), "");
  EXPECT_EQ(read_file_bytes(done), "whole");
  EXPECT_EQ(read_file_bytes(kept), "mine");
}

// The coordinator and the worker do not install it: a registration there does nothing.
TEST_F(InterruptCleanupTest, WithoutTheCleanupInstalledNothingIsRemoved) {
  const std::string path = (dir / "out.bin").string();
  EXPECT_EXIT(
      {
        AtomicFile f(path);
        std::signal(SIGTERM, SIG_DFL);
        std::raise(SIGTERM);
      },
      ::testing::KilledBySignal(SIGTERM), "");
  EXPECT_TRUE(fs::exists(path + ".tmp"));
}

}  // namespace
}  // namespace tessera
