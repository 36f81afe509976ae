// Issue 22: ended jobs leave memory (archive.h). Once a job's end is durable and its image
// and checkpoint hold its whole film, the reaper's tick archives it: its row keeps its last
// status, the coordinator forgets it, and everything a client asks of it (status, the list,
// its image, requeue, delete, priority, a liar found later) is answered from the row, the
// same as before, across a restart too.
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

using testing::files_under;

class ArchiveTest : public CoordinatorTest {
 protected:
  // Reaper ticks until no ended job is left in memory (a writer may be finishing).
  bool settle() {
    for (int i = 0; i < 500; ++i) {
      c->expire_leases();
      bool ended_in_memory = false;
      for (const v1::JobStatus& s : c->list()) ended_in_memory |= !job_live(s.state());
      if (!ended_in_memory) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return false;
  }
  void merge_some(uint64_t w, int n) {
    for (int i = 0; i < n; ++i) {
      const v1::GetTaskResponse r = c->get_task(w);
      if (r.tasks_size() == 0) return;
      ASSERT_TRUE(c->submit_result(render_task(r.tasks(0), w)).accepted());
    }
  }
  // What a status says but for the times and its tiles (an archived one keeps no tiles).
  static v1::JobStatus comparable(v1::JobStatus s) {
    s.clear_tiles();
    s.clear_elapsed_seconds();
    return s;
  }
  std::string image_bytes(const std::string& id, std::optional<int> frame = std::nullopt) {
    return c->image(id, true, false, frame).exr();
  }
};

TEST_F(ArchiveTest, AnEndedStillLeavesMemoryAndAnswersAsBefore) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s), "ann");
  drain(worker());
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const v1::JobStatus before = c->status(id, false), before_tiles = c->status(id, true);
  const std::string exr = image_bytes(id);
  EXPECT_TRUE(fs::exists(image_path(id, "checkpoint")));
  ASSERT_TRUE(settle());
  EXPECT_TRUE(c->list().empty()) << "an archived job is not in memory";
  // A DONE job is never requeued, and its image holds its film: its checkpoint goes.
  EXPECT_FALSE(fs::exists(image_path(id, "checkpoint")));
  EXPECT_TRUE(fs::exists(image_path(id, "image.exr")));
  const v1::JobStatus after = c->status(id, false);
  EXPECT_EQ(comparable(after).SerializeAsString(), comparable(before).SerializeAsString())
      << after.DebugString() << before.DebugString();
  // GetJob's tile map, as the job in memory (compacted) had it.
  v1::JobStatus tiles = c->status(id, true);
  tiles.clear_elapsed_seconds();
  v1::JobStatus tiles_before = before_tiles;
  tiles_before.clear_elapsed_seconds();
  EXPECT_EQ(tiles.tiles_size(), int(s.tile_count()));
  EXPECT_EQ(tiles.SerializeAsString(), tiles_before.SerializeAsString());
  EXPECT_EQ(image_bytes(id), exr);
  const v1::JobList page = c->list(10, "");
  ASSERT_EQ(page.jobs_size(), 1);
  EXPECT_EQ(page.total(), 1u);
  EXPECT_EQ(page.jobs(0).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->recent(10).size(), 1u);
  EXPECT_EQ(c->job_counts()[v1::JobStatus::DONE], 1u);
  EXPECT_TRUE(c->wait_for_end(id, 0));
  EXPECT_EQ(c->wait_for_change(id, 0, 0).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->cancel(id).state(), v1::JobStatus::DONE);  // nothing to cancel
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // A restart leaves it archived: nothing is read back into memory, its files stay.
  restart(c, options(), &t);
  EXPECT_TRUE(c->list().empty());
  EXPECT_EQ(c->counters().jobs_restored, 0u);
  EXPECT_EQ(comparable(c->status(id, false)).SerializeAsString(), comparable(before).SerializeAsString());
  EXPECT_EQ(image_bytes(id), exr);
  // Changed only by its owner; deleted, it leaves nothing.
  EXPECT_EQ(refused([&] { c->remove(id, "bob", false); }), RequestError::Code::kPermissionDenied);
  EXPECT_EQ(refused([&] { c->set_priority(id, 3, "bob", false); }), RequestError::Code::kPermissionDenied);
  EXPECT_EQ(c->set_priority(id, 3, "ann", false).priority(), 3);
  EXPECT_EQ(c->list(0, "").jobs(0).priority(), 3);
  EXPECT_EQ(refused([&] { c->requeue(id); }), RequestError::Code::kFailedPrecondition);  // DONE
  EXPECT_TRUE(c->list().empty());                                                        // refused from its row
  EXPECT_GT(c->remove(id, "ann", false), 0u);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
  EXPECT_EQ(refused([&] { c->status(id, false); }), RequestError::Code::kNotFound);
  EXPECT_EQ(c->list(0, "").jobs_size(), 0);
  EXPECT_EQ(c->counters().jobs_deleted, 1u);
}

TEST_F(ArchiveTest, AnArchivedSequenceAnswersForEveryFrame) {
  const RenderSettings s = job_settings();
  v1::SubmitJobRequest r = request(s);
  for (int f : {4, 5, 6}) r.add_frames(f);
  const std::string id = c->submit(r, "ann");
  const uint64_t w = worker();
  merge_some(w, int(s.tile_count()) * 3 + 2);  // frame 4 done, frame 5 begun, frame 6 never started
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const v1::JobStatus before = c->status(id, false);
  const v1::JobStatus five = c->status(id + "-f5", false);
  const std::string four = image_bytes(id, 4), partial = image_bytes(id, 5);
  ASSERT_TRUE(settle());
  EXPECT_TRUE(c->list().empty());
  const v1::JobStatus after = c->status(id, false);
  EXPECT_EQ(comparable(after).SerializeAsString(), comparable(before).SerializeAsString())
      << after.DebugString() << before.DebugString();
  ASSERT_EQ(after.frames_size(), 3);
  const v1::JobList listed = c->list(10, "");  // a list counts the frames, the status lists them
  ASSERT_EQ(listed.jobs_size(), 1);
  EXPECT_EQ(listed.jobs(0).frames_size(), 0);
  EXPECT_EQ(listed.jobs(0).frames_total(), 3u);
  EXPECT_EQ(c->recent(10).at(0).frames_size(), 0);  // (the summary's frames skipped unread)
  EXPECT_EQ(c->recent(10).at(0).frames_done(), 1u);
  const v1::JobStatus page = c->status(id, true, {}, FrameRange{1, 1});  // /api/jobs/<id>'s pages
  ASSERT_EQ(page.frames_size(), 1);
  EXPECT_EQ(page.frames(0).frame(), 5);
  EXPECT_EQ(page.current_frame_job(), id + "-f5");  // the last started
  EXPECT_EQ(after.frames(0).state(), v1::JobStatus::DONE);
  EXPECT_EQ(after.frames(1).state(), v1::JobStatus::CANCELLED);
  EXPECT_TRUE(after.frames(2).job_id().empty());
  const v1::JobStatus five_after = c->status(id + "-f5", false);
  EXPECT_EQ(five_after.state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(five_after.samples_done(), five.samples_done());
  EXPECT_EQ(five_after.frame_passes_done(), five.frame_passes_done());
  EXPECT_EQ(five_after.sequence(), id);
  EXPECT_EQ(c->status(id + "-f4", false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(refused([&] { c->status(id + "-f6", false); }), RequestError::Code::kNotFound);  // never started
  EXPECT_EQ(image_bytes(id, 4), four);
  EXPECT_EQ(image_bytes(id, 5), partial);
  EXPECT_EQ(image_bytes(id + "-f4"), four);
  EXPECT_EQ(refused([&] { c->image(id); }), RequestError::Code::kInvalidArgument);  // which frame?
  EXPECT_EQ(refused([&] { c->image(id, true, false, 7); }), RequestError::Code::kNotFound);
  EXPECT_EQ(refused([&] { c->image(id, true, false, 6); }), RequestError::Code::kFailedPrecondition);
  EXPECT_EQ(refused([&] { c->remove(id + "-f4"); }), RequestError::Code::kFailedPrecondition);
  // Requeued from its row and checkpoints: the frames not done render, bit for bit.
  restart(c, options(), &t);
  EXPECT_EQ(c->requeue(id, "ann", false).state(), v1::JobStatus::RUNNING);
  drain(worker());
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_EQ(c->status(id, false).frames_done(), 3u);
  for (int f : {4, 5, 6}) {
    RenderSettings frame = s;
    frame.frame = f;
    EXPECT_TRUE(same_film_as_exr(local(frame), read_exr(image_path(id + "-f" + std::to_string(f), "image.exr")))) << f;
  }
  EXPECT_TRUE(fs::exists(image_path(id + "-f4", "checkpoint")));  // kept while a requeue may need it
  ASSERT_TRUE(settle());
  for (int f : {4, 5, 6}) {  // DONE: each frame's image holds its film
    EXPECT_FALSE(fs::exists(image_path(id + "-f" + std::to_string(f), "checkpoint"))) << f;
    EXPECT_TRUE(fs::exists(image_path(id + "-f" + std::to_string(f), "image.exr"))) << f;
  }
  c->remove(id);
  EXPECT_EQ(files_under(dir + "/jobs") + files_under(dir + "/scenes"), 0u);
}

TEST_F(ArchiveTest, AnArchivedCancelledJobIsRequeuedBitIdentically) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const uint64_t w = worker();
  merge_some(w, 5);
  c->cancel(id);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  const v1::JobStatus tiles_before = c->status(id, true);
  ASSERT_TRUE(settle());
  const v1::JobStatus tiles = c->status(id, true);  // a map of a job that did not finish
  ASSERT_EQ(tiles.tiles_size(), tiles_before.tiles_size());
  for (int i = 0; i < tiles.tiles_size(); ++i)
    EXPECT_EQ(tiles.tiles(i).SerializeAsString(), tiles_before.tiles(i).SerializeAsString()) << i;
  EXPECT_TRUE(fs::exists(image_path(id, "checkpoint")));  // kept for this
  const uint64_t merged = c->counters().results_merged;
  EXPECT_EQ(c->requeue(id).state(), v1::JobStatus::RUNNING);
  EXPECT_FALSE(c->list().empty());  // back in memory, live
  drain(w);
  ASSERT_TRUE(c->wait_for_end(id, 10));
  EXPECT_EQ(c->counters().results_merged - merged, size_t(s.tile_count()) * 3 - 5);  // only what it lacked
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  ASSERT_TRUE(settle());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
}

// Memory follows the live work: a hundred jobs done leave nothing in memory, and the list
// still pages through them all in submission order.
TEST_F(ArchiveTest, ManyEndedJobsLeaveNothingInMemory) {
  std::vector<std::string> ids;
  RenderSettings s = job_settings();
  s.camera.width = s.camera.height = 8;
  s.tile_size = 8;
  const uint64_t w = worker();
  for (int i = 0; i < 100; ++i) {
    ids.push_back(c->submit(request(s)));
    drain(w);
    if (i % 10 == 9) c->expire_leases();
  }
  ASSERT_TRUE(c->wait_for_end(ids.back(), 10));
  ASSERT_TRUE(settle());
  EXPECT_TRUE(c->list().empty());
  std::vector<std::string> seen;
  std::string token;
  do {
    const v1::JobList page = c->list(30, token);
    for (const v1::JobStatus& j : page.jobs()) {
      seen.push_back(j.id());
      EXPECT_EQ(j.state(), v1::JobStatus::DONE);
    }
    token = page.next_page_token();
  } while (!token.empty());
  EXPECT_EQ(seen, ids);
  const std::vector<v1::JobStatus> recent = c->recent(10);
  ASSERT_EQ(recent.size(), 10u);
  EXPECT_EQ(recent.back().id(), ids.back());
  EXPECT_EQ(c->job_counts()[v1::JobStatus::DONE], 100u);
}

}  // namespace
}  // namespace tessera
