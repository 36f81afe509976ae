// Watching a job: `tessera watch` and `submit --wait` say why a live job waits and why it
// failed.
#include <fstream>
#include <string>
#include <thread>

#include "tests/client/farm_client_fixture.h"

namespace tessera {
namespace {

// A live job's error (here why it waits: a task failed on the only worker) is printed by
// whoever watches it, once a text, with -q too: a farm of one no longer waits in silence;
// and the watch ends saying why the job failed.
TEST_F(FarmClient, AWatchSaysWhyALiveJobWaits) {
  SubmitRequest r = request({});
  ASSERT_EQ(submit_job(*stub, r, ctx), 0) << err.text();
  const std::string id = coordinator->list().at(0).id();
  const std::string err_path = (dir / "watch.err").string();
  FarmContext watching = ctx;
  watching.err = std::fopen(err_path.c_str(), "w");
  ASSERT_NE(watching.err, nullptr);
  int rc = -1;
  std::thread watcher([&] { rc = watch_job(*stub, id, watching); });
  v1::RegisterRequest reg;
  reg.set_version(kProtocolVersion);
  reg.set_name("lonely");
  reg.set_threads(1);
  const uint64_t w = coordinator->register_worker(reg).worker_id();
  coordinator->release(w, coordinator->get_task(w).tasks(0).task_id(), "the scene would not load: no memory");
  const auto printed = [&] {
    std::ifstream f(err_path);
    return std::string(std::istreambuf_iterator<char>(f), {});
  };
  for (int i = 0; i < 600 && printed().find("note:") == std::string::npos; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  // A second worker fails one too: the job fails, and the watch ends saying why.
  reg.set_name("second");
  const uint64_t w2 = coordinator->register_worker(reg).worker_id();
  coordinator->release(w2, coordinator->get_task(w2).tasks(0).task_id(), "the scene would not load: no memory");
  watcher.join();
  std::fclose(watching.err);
  EXPECT_EQ(rc, 1);
  const std::string text = printed();
  EXPECT_NE(text.find("tessera: job " + id + ": tasks failed on 2 workers: the scene would not load: no memory\n"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("note: job " + id + ": a task failed on registration " + std::to_string(w) +
                      ": the scene would not load: no memory (the job fails once tasks fail on 2 workers; 1 so far; "
                      "that worker is not given its tasks for 30 s)"),
            std::string::npos)
      << text;
  EXPECT_EQ(text.find("note:"), text.rfind("note:")) << text;  // once
}

}  // namespace
}  // namespace tessera
