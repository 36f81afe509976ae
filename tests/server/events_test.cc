// Events (server/events.h): what happened, who did it and why, through the whole
// coordinator and into the database; the log line that cannot be forged.
#include "server/events.h"

#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

std::vector<std::string> kinds(const std::vector<Event>& events) {
  std::vector<std::string> out;
  for (const Event& e : events) out.push_back(e.kind);
  return out;
}
const Event& only(const std::vector<Event>& events, const std::string& kind) {
  static const Event none;
  const Event* found = &none;
  int n = 0;
  for (const Event& e : events)
    if (e.kind == kind) found = &e, ++n;
  EXPECT_EQ(n, 1) << kind;
  return *found;
}

class EventsTest : public CoordinatorTest {};

TEST_F(EventsTest, AJobsLifeIsToldWithWhoDidWhatInOrder) {
  const uint64_t w = worker();
  v1::SubmitJobRequest r = request(job_settings());
  r.set_name("shot <1>");
  const std::string id = c->submit(r, "alice");
  c->set_priority(id, 5, "alice", false);
  drain(w);
  c->unregister(w);
  const std::vector<Event> all = c->events("", 0, 100, true);
  EXPECT_EQ(kinds(all), (std::vector<std::string>{"coordinator.started", "worker.registered", "job.submitted",
                                                  "job.priority", "job.started", "job.done", "worker.unregistered"}));
  for (size_t i = 1; i < all.size(); ++i) {
    EXPECT_GT(all[i].id, all[i - 1].id);
    EXPECT_GE(all[i].time, all[i - 1].time);
  }
  EXPECT_GT(all[0].time, 1.7e9);  // the wall clock, not the coordinator's own
  const Event& submitted = only(all, "job.submitted");
  EXPECT_EQ(submitted.job, id);
  EXPECT_EQ(submitted.who, "alice");
  EXPECT_EQ(submitted.detail, "'shot <1>', 48x36, 10 spp");
  EXPECT_EQ(only(all, "job.priority").detail, "priority 5");
  EXPECT_EQ(only(all, "worker.registered").worker, "test");
  EXPECT_EQ(only(all, "worker.registered").detail, "threads 1");
  EXPECT_EQ(only(all, "job.done").who, "");  // the coordinator's own doing
  EXPECT_NE(only(all, "worker.unregistered").detail.find("tasks done"), std::string::npos);

  // One job's; the newest few; the oldest after one seen (--follow).
  EXPECT_EQ(kinds(c->events(id, 0, 100, true)),
            (std::vector<std::string>{"job.submitted", "job.priority", "job.started", "job.done"}));
  EXPECT_EQ(kinds(c->events("", 0, 2, true)), (std::vector<std::string>{"job.done", "worker.unregistered"}));
  EXPECT_EQ(kinds(c->events("", all[4].id, 1, false)), (std::vector<std::string>{"job.done"}));
  EXPECT_TRUE(c->events("", all.back().id, 100, false).empty());
}

TEST_F(EventsTest, CancelRequeueAndDeleteSayWhoAndSequencesTellTheirFrames) {
  const std::string id = c->submit(request(job_settings()), "alice");
  c->cancel(id, "root", true);
  c->requeue(id, "alice", false);
  c->remove(id, "alice", false);
  v1::SubmitJobRequest r = request(job_settings());
  for (int f : {3, 4}) r.add_frames(f);
  const std::string seq = c->submit(r, "bob");
  drain(worker());
  const std::vector<Event> all = c->events("", 0, 100, true);
  std::vector<std::string> cancelled_by;  // by root, then (live again, deleted) by alice
  for (const Event& e : all)
    if (e.kind == "job.cancelled") cancelled_by.push_back(e.who);
  EXPECT_EQ(cancelled_by, (std::vector<std::string>{"root", "alice"}));
  EXPECT_EQ(only(all, "job.requeued").who, "alice");
  EXPECT_EQ(only(all, "job.deleted").who, "alice");
  EXPECT_EQ(only(all, "job.deleted").job, id);
  EXPECT_EQ(kinds(c->events(seq, 0, 100, true)),
            (std::vector<std::string>{"job.submitted", "job.started", "frame.done", "frame.done", "job.done"}));
  EXPECT_EQ(c->events(seq, 0, 100, true)[2].detail, "frame 3");
  EXPECT_EQ(c->events(seq, 0, 100, true)[0].detail, "48x36, 10 spp, 2 frames");
}

TEST_F(EventsTest, FailuresAndLostWorkersSayWhy) {
  const std::string id = c->submit(request(job_settings()), "alice");
  const uint64_t w = worker();
  const v1::GetTaskResponse r = c->get_task(w);
  ASSERT_EQ(r.tasks_size(), 1);
  c->release(w, r.tasks(0).task_id(), "std::bad_alloc: out of memory");
  // Its next failure on the job is counted, not logged again: one worker failing a job's
  // tasks over and over pushed the farm's history out of the log (the newest 100,000 kept).
  t += JobLifecycle::kFirstRestSeconds;  // (it rests from the job's tasks meanwhile)
  const v1::GetTaskResponse again = c->get_task(w);
  ASSERT_EQ(again.tasks_size(), 1);
  c->release(w, again.tasks(0).task_id(), "std::bad_alloc: out of memory, again");
  EXPECT_EQ(c->counters().tasks_failed, 2u);
  t += c->options().worker_timeout_seconds + 1;
  c->expire_leases();
  const std::vector<Event> all = c->events("", 0, 100, true);
  const Event& failed = only(all, "task.failed");
  EXPECT_EQ(failed.job, id);
  EXPECT_EQ(failed.worker, "test");
  EXPECT_EQ(failed.detail, "std::bad_alloc: out of memory");
  EXPECT_EQ(only(all, "worker.lost").worker, "test");
  EXPECT_NE(only(all, "worker.lost").detail.find("silent for"), std::string::npos);
}

TEST_F(EventsTest, EventsAreKeptAcrossARestart) {
  const std::string id = c->submit(request(job_settings()), "alice");
  restart(c, options(), &t);
  const std::vector<Event> all = c->events("", 0, 100, true);
  EXPECT_EQ(kinds(all), (std::vector<std::string>{"coordinator.started", "job.submitted", "coordinator.started"}));
  EXPECT_EQ(all[1].job, id);
  EXPECT_EQ(all[2].detail, "jobs taken up: 1");
}

TEST(EventLine, AValueCannotStartALineOrForgeAField) {
  const Event e{0, 0, "job.failed", "abc", "", "alice", "boom\nevent=job.done who=root \"x\""};
  EXPECT_EQ(event_line(e), R"(event=job.failed job=abc who=alice detail="boom\nevent=job.done who=root \"x\"")");
  const Event plain{0, 0, "worker.lost", "", "node-1", "farm", ""};
  EXPECT_EQ(event_line(plain), "event=worker.lost worker=node-1 who=farm");
  const Event bytes{0, 0, "job.submitted", "j", "", "", std::string("\xff\x01=", 3)};
  EXPECT_EQ(event_line(bytes).find('\x01'), std::string::npos) << event_line(bytes);
}

// The database keeps the newest kMaxEvents: a farm that runs for months stays flat.
TEST(EventStore, KeepsTheNewestAndForgetsTheRest) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_events_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  {
    SqliteJobStore store(dir.string());
    for (uint64_t done = 0; done < kMaxEvents + 10; done += 5000) {
      std::vector<Event> batch(std::min<uint64_t>(5000, kMaxEvents + 10 - done));
      for (Event& e : batch) e = {0, 1.8e9, "job.started", "j", "", "", ""};
      store.append_events(batch);
      EXPECT_EQ(batch.back().id, done + batch.size());
    }
    EXPECT_EQ(store.events("", 0, 1, true).front().id, kMaxEvents + 10);
    EXPECT_EQ(store.events("", 0, 1, false).front().id, 11u);  // the first ten are gone
    EXPECT_EQ(store.events("j", kMaxEvents, 100, false).size(), 10u);
    EXPECT_TRUE(store.events("other", 0, 100, true).empty());
  }
  SqliteJobStore again(dir.string());  // ids go on counting after a restart
  std::vector<Event> one{{0, 1.8e9, "coordinator.started", "", "", "", ""}};
  again.append_events(one);
  EXPECT_EQ(one[0].id, kMaxEvents + 11);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
