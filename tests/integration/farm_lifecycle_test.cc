// Issue 22, a job's life after submit through the real binaries: requeue (bit-identical to
// tessera render) and delete (the data folder shrinks back), each with the coordinator
// killed -9 just after its commit point; retention (--keep-ended); paging through jobs.
#include "tests/core/test_paths.h"
#include "tests/integration/farm_fixture.h"

namespace tessera {
namespace {

std::string first_line(const std::string& s) { return s.substr(0, s.find('\n')); }

using testing::files_under;

class Lifecycle : public Farm {
 protected:
  CommandResult tessera(const std::string& args) { return run(args + " --coordinator " + grpc_addr, dir); }
  std::string state_of(const std::string& id) {
    const CommandResult r = tessera("status " + id + " --json");
    if (r.code != 0) return "gone: " + r.err;
    const nlohmann::json j = nlohmann::json::parse(first_line(r.out));
    return j.value("state", "QUEUED");
  }
  // Waits up to `seconds` for the job's state to be `state`.
  bool wait_for(const std::string& id, const std::string& state, double seconds = 60) {
    for (auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
         std::chrono::steady_clock::now() < until; std::this_thread::sleep_for(std::chrono::milliseconds(50)))
      if (state_of(id) == state) return true;
    return false;
  }
  void kill_and_restart(const std::vector<std::string>& extra = {}) {
    coordinator->signal(SIGKILL);
    coordinator->wait(10);
    const std::string old = grpc_addr;
    start_coordinator(old, "2", extra);  // the same address: the worker finds it again
  }
};

// A cancelled job requeued goes on from its checkpoint; the coordinator killed just after
// the requeue's record takes it up again at its restart. Its image is tessera render's.
TEST_F(Lifecycle, ARequeueSurvivesAKillAfterItsRecordAndTheImageIsTheLocalOne) {
  const std::string flags = "-r 96 72 -s 32 --pass-spp 4 -m 6 --seed 5 --tile 16";
  const std::string local = local_render(flags);
  start_coordinator("127.0.0.1:0", "2", {"--test-commit-delay-ms", "8000", "--checkpoint-seconds", "0"});
  start_worker();
  const CommandResult sub = tessera("submit " + kScene + " " + flags);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = first_line(sub.out);
  for (int i = 0; i < 400; ++i) {  // some samples in, not all
    const CommandResult s = tessera("status " + id + " --json");
    if (s.code == 0 && nlohmann::json::parse(first_line(s.out)).value("samples_done", uint64_t(0)) != 0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  }
  ASSERT_EQ(tessera("cancel " + id).code, 0);
  ASSERT_TRUE(wait_for(id, "CANCELLED"));
  std::thread requeue([&] { tessera("requeue " + id); });        // its record, then 8 s of delay
  std::this_thread::sleep_for(std::chrono::milliseconds(4000));  // past the record, in the delay
  kill_and_restart();
  requeue.join();
  ASSERT_TRUE(wait_for(id, "DONE", 120)) << state_of(id);
  const std::string out = (dir / "farm.exr").string();
  ASSERT_EQ(tessera("fetch " + id + " -f " + out).code, 0);
  expect_same_pixels(local, out);
}

// Issue 23: a DONE job's image file truncated on the coordinator's disk was fetched with
// exit 0 as a 300-byte file. A final image is decoded before it is served (once per
// version): damaged, the fetch fails saying so and writes nothing; whole, it is served.
TEST_F(Lifecycle, ADamagedFinalImageIsAnErrorNeverADownload) {
  start_coordinator("127.0.0.1:0", "2");
  start_worker();
  const std::string out = (dir / "whole.exr").string();
  const CommandResult sub = tessera("submit " + kScene + " -r 32 24 -s 4 --pass-spp 4 --wait -q -f " + out);
  ASSERT_EQ(sub.code, 0) << sub.err;
  const std::string id = first_line(sub.out).substr(0, 16);
  const fs::path image = dir / "data" / "jobs" / id / "image.exr";
  ASSERT_TRUE(fs::exists(image)) << image;
  ASSERT_EQ(tessera("fetch " + id + " -f " + (dir / "again.exr").string()).code, 0);
  fs::resize_file(image, 300);
  for (const char* name : {"cut.exr", "cut.png"}) {
    const CommandResult r = tessera("fetch " + id + " -f " + (dir / name).string());
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.err.find("its final image on the coordinator is damaged or cut short"), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find(dir.string()), std::string::npos) << "no server path: " << r.err;
    EXPECT_FALSE(fs::exists(dir / name));
  }
}

// A delete killed just after its record: the restart finds no job and removes its files,
// so the data folder holds nothing of it. A delete that runs through frees the same.
TEST_F(Lifecycle, ADeleteSurvivesAKillAfterItsRecordAndTheDataFolderShrinksBack) {
  start_coordinator("127.0.0.1:0", "2", {"--test-commit-delay-ms", "8000"});
  start_worker(2);
  const std::string a = (dir / "a.exr").string(), b = (dir / "b.exr").string();
  ASSERT_EQ(submit_wait(kScene, kFlags, a).code, 0);
  ASSERT_EQ(submit_wait(kScene, kFlags + std::string(" --frames 1-2"), (dir / "b.####.exr").string()).code, 0);
  // kubectl's way: a header over the rows, --no-headers for scripts.
  const CommandResult table = tessera("jobs");
  ASSERT_EQ(table.code, 0);
  EXPECT_EQ(first_line(table.out).rfind("ID ", 0), 0u) << table.out;
  for (const char* column : {"STATE", "PROGRESS", "FRAMES", "PRIORITY", "OWNER", "WORKERS", "ELAPSED", "ETA", "NAME"})
    EXPECT_NE(first_line(table.out).find(column), std::string::npos) << column;
  EXPECT_NE(table.out.find("  2/2  "), std::string::npos) << table.out;  // the sequence's frames
  const CommandResult list = tessera("jobs --no-headers");
  ASSERT_EQ(list.code, 0);
  std::vector<std::string> ids;
  for (std::istringstream in(list.out); std::getline(in, ids.emplace_back(), ' ');) in.ignore(1 << 20, '\n');
  ids.pop_back();
  ASSERT_EQ(ids.size(), 2u) << list.out;
  const fs::path data = dir / "data";
  EXPECT_GT(files_under(data / "jobs"), 0u);
  EXPECT_GT(files_under(data / "scenes"), 0u);  // kept while a job names it
  std::thread remove([&] { tessera("delete " + ids[0]); });
  std::this_thread::sleep_for(std::chrono::milliseconds(4000));  // past the record, in the delay
  kill_and_restart();
  remove.join();
  EXPECT_NE(tessera("status " + ids[0]).code, 0);
  EXPECT_FALSE(fs::exists(data / "jobs" / ids[0]));
  EXPECT_GT(files_under(data / "scenes"), 0u);  // the sequence names the scene still
  kill_and_restart();                           // no delay now
  const CommandResult del = tessera("delete " + ids[1]);
  ASSERT_EQ(del.code, 0) << del.err;
  EXPECT_NE(del.out.find("deleted"), std::string::npos) << del.out;
  EXPECT_EQ(files_under(data / "jobs") + files_under(data / "scenes"), 0u);
  EXPECT_EQ(tessera("jobs").out, "");
}

// --keep-ended: an ended job goes by itself once it has been ended that long.
TEST_F(Lifecycle, EndedJobsGoAfterKeepEnded) {
  start_coordinator("127.0.0.1:0", "2", {"--keep-ended", "2s"});
  start_worker(2);
  const std::string out = (dir / "farm.exr").string();
  ASSERT_EQ(submit_wait(kScene, kFlags, out).code, 0);
  const std::string id = first_line(tessera("jobs --no-headers").out).substr(0, 16);
  EXPECT_EQ(state_of(id), "DONE");
  bool gone = false;
  for (int i = 0; i < 200 && !gone; ++i, std::this_thread::sleep_for(std::chrono::milliseconds(50)))
    gone = tessera("status " + id).code != 0;
  EXPECT_TRUE(gone);
  EXPECT_EQ(files_under(dir / "data" / "jobs") + files_under(dir / "data" / "scenes"), 0u);
  EXPECT_TRUE(fs::exists(out));  // what the client downloaded is its own
}

// A --keep-ended the coordinator cannot read stops it at once, saying what it takes.
TEST_F(Lifecycle, ABadKeepEndedIsRefusedSayingWhatItTakes) {
  for (const std::string bad : {"7x", "-1d", "d", "1e20s", "''", "7d5"}) {
    const std::string err = (dir / "keep.err").string();
    const int status = std::system((kBin + "/tessera-coordinator --listen 127.0.0.1:0 --http 127.0.0.1:0 --data " +
                                    (dir / "data").string() + " --keep-ended " + bad + " >/dev/null 2>" + err)
                                       .c_str());
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 2) << bad;
    const std::string said = slurp(err);
    EXPECT_NE(said.find("--keep-ended"), std::string::npos) << bad << ": " << said;
    EXPECT_NE(said.find("expected a duration such as 7d, 12h, 30m, 45s or forever"), std::string::npos)
        << bad << ": " << said;
  }
}

// Found by audit: a second coordinator on the same data folder took up every job beside the
// first (both wrote the same checkpoints; each start removed the other's uploads), and one
// on the same address shared the port (gRPC's SO_REUSEPORT). Both are refused, naming why.
TEST_F(Lifecycle, ASecondCoordinatorOnTheSameDataFolderOrPortIsRefused) {
  start_coordinator();
  const std::string err = (dir / "second.err").string();
  int status = std::system((kBin + "/tessera-coordinator --listen 127.0.0.1:0 --http 127.0.0.1:0 --data " +
                            (dir / "data").string() + " >/dev/null 2>" + err)
                               .c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0);
  std::string said = slurp(err);
  EXPECT_NE(said.find("data folder " + (dir / "data").string() + " is in use by another coordinator (process "),
            std::string::npos)
      << said;
  status = std::system((kBin + "/tessera-coordinator --listen " + grpc_addr + " --http 127.0.0.1:0 --data " +
                        (dir / "other").string() + " >/dev/null 2>" + err)
                           .c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) != 0);
  said = slurp(err);
  EXPECT_NE(said.find("cannot listen on " + grpc_addr), std::string::npos) << said;
}

// A priority set after submit orders the queue; `jobs` pages through every job.
TEST_F(Lifecycle, PriorityAfterSubmitAndJobsInPages) {
  start_coordinator();
  std::vector<std::string> ids;
  for (int i = 0; i < 3; ++i) {
    const CommandResult r = tessera("submit " + kScene + " " + kFlags);
    ASSERT_EQ(r.code, 0) << r.err;
    ids.push_back(first_line(r.out));
  }
  const CommandResult p = tessera("priority " + ids[2] + " 9");
  ASSERT_EQ(p.code, 0) << p.err;
  EXPECT_NE(tessera("status " + ids[2] + " --json").out.find("\"priority\":9"), std::string::npos);
  EXPECT_EQ(tessera("priority " + ids[1] + " -4").code, 0);
  EXPECT_NE(tessera("status " + ids[1] + " --json").out.find("\"priority\":-4"), std::string::npos);
  start_worker();
  ASSERT_TRUE(wait_for(ids[2], "DONE"));
  EXPECT_NE(state_of(ids[1]), "DONE");  // the lowest goes last
  const CommandResult list = tessera("jobs --json");
  EXPECT_EQ(nlohmann::json::parse(first_line(list.out))["jobs"].size(), 3u);
  const CommandResult bad = tessera("requeue " + ids[0]);
  EXPECT_EQ(bad.code, 1);
  EXPECT_NE(bad.err.find("only a FAILED or CANCELLED job can be requeued"), std::string::npos) << bad.err;
}

}  // namespace
}  // namespace tessera
