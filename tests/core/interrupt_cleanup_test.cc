// A process ended by Ctrl-C (or a kill) leaves no half-written file where it installed the
// cleanup (core/io/interrupt_cleanup.h): an AtomicFile's and an EXR writer's temporary
// files are removed, and the process still ends by the signal.
#include "core/io/interrupt_cleanup.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
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
        ExrWriter w(path, Rect{0, 0, 8, 4}, Rect{0, 0, 8, 4}, {}, true, 0);
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

namespace tessera {
namespace {

// Found by audit: two tessera commands writing one output shared its temporary (OUT.tmp,
// opened with O_TRUNC): the second truncated and wrote into the first's, the first renamed
// that into place, the second failed, and a fetch said it had succeeded with the other
// job's image. With use_unique_temporaries() (the tessera command's), each process has its
// own: a child's whole file lands even though its parent wrote and committed the same
// output in between.
TEST(UniqueTemporaries, TwoProcessesWritingOneOutputKeepApart) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_unique_tmp_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "out.bin").string();
  EXPECT_EQ(temporary_path(path), path + ".tmp");  // (the default: a coordinator's fixed names)
  int ready[2], go[2];
  ASSERT_EQ(::pipe(ready), 0);
  ASSERT_EQ(::pipe(go), 0);
  const std::string child_bytes(1 << 20, 'A'), parent_bytes(1 << 19, 'B');
  const pid_t child = ::fork();
  if (child == 0) {
    use_unique_temporaries();
    int status = 0;
    try {
      AtomicFile f(path);
      f.append(child_bytes.substr(0, child_bytes.size() / 2));
      char c = 1;
      if (::write(ready[1], &c, 1) != 1 || ::read(go[0], &c, 1) != 1) std::_Exit(4);
      f.append(child_bytes.substr(child_bytes.size() / 2));
      f.commit();
    } catch (const std::exception&) {
      status = 5;
    }
    std::_Exit(status);
  }
  use_unique_temporaries();
  EXPECT_EQ(temporary_path(path), path + "." + std::to_string(::getpid()) + ".tmp");
  char c = 0;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);  // the child has its temporary half written
  write_file_atomic(path, parent_bytes);
  ASSERT_EQ(::write(go[1], &c, 1), 1);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  EXPECT_EQ(read_file_bytes(path), child_bytes);  // the last commit, whole
  use_unique_temporaries(false);                  // (the other tests of this process expect the fixed names)
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
