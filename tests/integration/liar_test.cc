// Verify by replay through the real binaries (issue 23): a worker that returns wrong but
// plausible sums (the hidden --test-lie) among honest ones, set up as the deploy recipes
// set workers up. Each registration's first tasks are checked (probation), so a liar is
// caught before its lies can stay in an image; what it merged is rendered again (the image
// is the bytes of `tessera render`); and only its own identity is refused: an enrolled
// worker's credential and name, never a token from the file that other workers share.
#include <nlohmann/json.hpp>
#include <thread>

#include "tests/integration/access_fixture.h"

namespace tessera {
namespace {

const std::string kLiarFlags = "-r 96 72 -s 32 --pass-spp 8 -m 4 --seed 3 --tile 16";  // 120 tasks

// The lines of `text` holding any of `words`.
std::string grep_lines(const std::string& text, const std::vector<std::string>& words) {
  std::string out, line;
  for (size_t at = 0; at < text.size();) {
    const size_t end = std::min(text.find('\n', at), text.size());
    line = text.substr(at, end - at);
    for (const std::string& w : words)
      if (line.find(w) != std::string::npos) {
        out += line + "\n";
        break;
      }
    at = end + 1;
  }
  return out;
}

class Liar : public Access {
 protected:
  // Waits until the status page lists `n` workers (so no task goes out before they are all
  // there: probation needs another worker to check); up to 30 s (a loaded 2-core machine
  // starting four workers once took more than 10).
  bool wait_for_workers(size_t n) {
    for (int i = 0; i < 600; ++i) {
      httplib::Client cli("127.0.0.1", http_port);
      auto res = cli.Get("/api/status", {{"Authorization", std::string("Bearer ") + kViewer}});
      if (res && res->status == 200 && nlohmann::json::parse(res->body)["workers"].size() == n) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }
  std::string metrics() {
    httplib::Client cli("127.0.0.1", http_port);
    const auto m = cli.Get("/metrics", {{"Authorization", std::string("Bearer ") + kViewer}});
    return m ? m->body : "";
  }
  // A job through the farm, --wait: its image must equal `tessera render`'s.
  void render_and_compare(const std::string& tag) {
    const std::string out = (dir / (tag + ".exr")).string(), local = (dir / "local.exr").string();
    const CommandResult r = tessera("submit " + kScene + " " + kLiarFlags + " --wait -q -f " + out, kAlice);
    ASSERT_EQ(r.code, 0) << r.err;
    if (!fs::exists(local)) {
      ASSERT_EQ(std::system((kBin + "/tessera render " + kScene + " " + kLiarFlags + " -q -f " + local).c_str()), 0);
    }
    // On a difference, what the client and the coordinator said (was the liar caught after
    // the job ended, say: a flag on the job) and the folder's name (TESSERA_KEEP_TEST_DIR=1
    // keeps it).
    SCOPED_TRACE("submit said: " + r.out + r.err + "\nin " + dir.string() +
                 "; coordinator's quarantines and checks:\n" +
                 grep_lines(slurp((dir / "coordinator.err").string()), {"quarantin", "check", "reset", "again"}));
    expect_same_pixels(local, out);
  }
};

// The shipped recipes' way: every worker enrols for a credential of its own. The liar is
// caught on probation at the default --verify-fraction (0.01), its credential and name are
// refused from then on (it exits), and the honest workers are untouched: one restarted
// enrols again and works. The liar under a new name is a new identity on probation: caught
// again, and again no lie is left in the image. (Once 1 run in 20 under load ended with one
// lied pass in one tile of the second job: an honest worker's run of passes leased on the
// liar's first pass of the tile, returned after the tile was rendered again and merged;
// now refused: VerifierTest.AResultLeasedBeforeItsTileWasTakenBackIsRefused.)
TEST_F(Liar, ALiarAmongEnrolledWorkersIsCaughtOnProbationAndOnlyItsIdentityIsRefused) {
  start_coordinator();
  start_enrolled("honest-1");
  // Runs of passes carry the tile's sums so far (maybe the liar's) and return them grown.
  start_enrolled("honest-2", {"--passes-per-task", "2"});
  start_enrolled("honest-3", {"--passes-per-task", "4"});
  Process& liar = start_enrolled("liar", {"--test-lie"});
  ASSERT_TRUE(wait_for_workers(4));
  render_and_compare("first");
  EXPECT_EQ(liar.wait(30), 1);  // its credential refused: quarantined
  EXPECT_NE(slurp((dir / "worker3.err").string()).find("is quarantined"), std::string::npos)
      << slurp((dir / "worker3.err").string());
  const std::string log = slurp((dir / "coordinator.err").string());
  EXPECT_NE(log.find("event=worker.quarantined worker=liar who=liar detail="), std::string::npos) << log;
  EXPECT_NE(metrics().find("tessera_workers_quarantined_total 1\n"), std::string::npos);

  // The same name may not enrol again.
  Process& again = start_enrolled("liar", {"--test-lie"});
  EXPECT_EQ(again.wait(30), 1);
  EXPECT_NE(slurp((dir / "worker4.err").string()).find("worker 'liar' is quarantined"), std::string::npos)
      << slurp((dir / "worker4.err").string());
  // An honest worker restarted enrols again and works; a worker with the file's shared
  // worker token was never refused; the liar as a new identity is on probation.
  workers[0]->signal(SIGTERM);
  EXPECT_EQ(workers[0]->wait(30), 0);
  start_enrolled("honest-1");
  start_worker(kWorker);
  Process& renamed = start_enrolled("liar-2", {"--test-lie"});
  ASSERT_TRUE(wait_for_workers(5));  // honest-1..3, the shared-token worker, liar-2
  render_and_compare("second");
  EXPECT_EQ(renamed.wait(30), 1);
  EXPECT_NE(metrics().find("tessera_workers_quarantined_total 2\n"), std::string::npos) << metrics();
}

// With one worker token from the file for every worker (the old recipes), a catch ends the
// liar's registration but never refuses the token, which its honest peers hold too: the
// liar registers again, and each registration is caught on probation again, so the image
// is still exact and an honest worker started after the catch is not locked out.
// (Once 1 run in 6 under load ended with a wrong image: the liar, registered again, got
// backups of others' tiles at a frame's end, which nobody checked; now they are checked.)
TEST_F(Liar, WithASharedWorkerTokenTheLiarIsCaughtEachTimeAndHonestWorkersAreNotLockedOut) {
  start_coordinator();
  start_worker(kWorker);
  start_worker(kWorker);
  start_worker(kWorker, std::vector<std::string>{"--test-lie"});
  ASSERT_TRUE(wait_for_workers(3));
  render_and_compare("first");
  const std::string m = metrics();
  EXPECT_EQ(m.find("tessera_workers_quarantined_total 0\n"), std::string::npos) << m;
  EXPECT_EQ(slurp((dir / "coordinator.err").string()).find("token 'farm' is quarantined"), std::string::npos);
  Process& late = start_worker(kWorker);  // after the catch: still welcome
  render_and_compare("second");
  late.signal(SIGTERM);
  EXPECT_EQ(late.wait(30), 0);
  const std::string said = slurp((dir / "worker3.err").string());
  EXPECT_NE(said.find("stopped after"), std::string::npos) << said;
  EXPECT_EQ(said.find("stopped after 0 tasks"), std::string::npos) << said;  // it worked
}

}  // namespace
}  // namespace tessera
