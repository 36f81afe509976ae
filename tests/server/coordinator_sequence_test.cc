// Sequences through the whole coordinator.
#include <nlohmann/json.hpp>

#include "server/status_http.h"
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

// ---- sequences -----------------------------------------------------------------------

class SequenceTest : public CoordinatorTest {
 protected:
  v1::SubmitJobRequest sequence(const std::vector<int>& frames) {
    v1::SubmitJobRequest r = request(job_settings());
    for (int f : frames) r.add_frames(f);
    return r;
  }
  RenderSettings frame(int n) const {
    RenderSettings s = job_settings();
    s.frame = n;
    return s;
  }
  bool frame_is_local(const std::string& id, int n) {
    const std::string path = dir + "/frame" + std::to_string(n) + ".exr";
    std::ofstream(path, std::ios::binary) << c->image(id, true, false, n).exr();
    const ExrImage img = read_exr(path);
    EXPECT_EQ(img.metadata.at("tessera/frame"), std::to_string(n));
    return same_film_as_exr(local(frame(n)), img);
  }
  std::map<int, v1::JobStatus::State> frame_states(const std::string& id) {
    std::map<int, v1::JobStatus::State> out;
    const v1::JobStatus st = c->status(id, false);
    for (const v1::FrameStatus& f : st.frames()) out[f.frame()] = f.state();
    return out;
  }
};

TEST_F(SequenceTest, EachFrameIsTheImageOfThatFrameAloneAndEarlierFramesGoFirst) {
  const std::string id = c->submit(sequence({7, 3, 5}));  // in the order given
  v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::QUEUED);
  EXPECT_EQ(st.frames_total(), 3u);
  EXPECT_EQ(st.frames_size(), 3);
  EXPECT_EQ(st.samples_total(), 3u * 48 * 36 * 10);
  EXPECT_EQ(st.tiles_total(), 3u * 9);  // counted without making a frame's film
  EXPECT_EQ(st.passes_total(), 3u);
  EXPECT_EQ(c->list().size(), 1u);  // the frames are in their sequence, not listed apart
  const uint64_t w = worker();
  std::vector<std::string> order;  // the job of each task, in the order handed out
  for (int guard = 0; guard < 1000; ++guard) {
    const v1::GetTaskResponse r = c->get_task(w);
    if (r.tasks_size() == 0) break;
    if (order.empty() || order.back() != r.tasks(0).job_id()) order.push_back(r.tasks(0).job_id());
    ASSERT_TRUE(c->submit_result(render_task(r.tasks(0), w)).accepted());
  }
  EXPECT_EQ(order, (std::vector<std::string>{id + "-f7", id + "-f3", id + "-f5"}));
  st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.frames_done(), 3u);
  EXPECT_EQ(st.samples_done(), st.samples_total());
  for (int n : {3, 5, 7}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  EXPECT_EQ(c->status(id + "-f5", false).sequence(), id);  // each frame's own job
  try {
    c->image(id);
    ADD_FAILURE() << "a sequence's image needs a frame";
  } catch (const RequestError& e) {
    EXPECT_NE(std::string(e.what()).find("--frame"), std::string::npos) << e.what();
  }
  EXPECT_THROW(c->image(id, true, false, 4), RequestError);  // not one of its frames
  EXPECT_THROW(c->cancel(id + "-f5"), RequestError);         // frames go with their sequence
}

TEST_F(SequenceTest, AWorkerWithRoomGetsTheNextFrameBeforeTheLastOneEnds) {
  const std::string id = c->submit(sequence({1, 2, 3, 4}));
  const uint64_t w = worker();
  // 9 tiles a frame: a worker asking for 20 tasks gets frame 1's and 2's first passes and
  // some of frame 3's, never waiting for frame 1 to finish.
  const v1::GetTaskResponse r = c->get_task(w, 20);
  ASSERT_EQ(r.tasks_size(), 20);
  std::map<std::string, int> per_job;
  for (const v1::Task& t : r.tasks()) ++per_job[t.job_id()];
  EXPECT_EQ(per_job[id + "-f1"], 9);
  EXPECT_EQ(per_job[id + "-f2"], 9);
  EXPECT_EQ(per_job[id + "-f3"], 2);
  const auto states = frame_states(id);
  EXPECT_EQ(states.at(1), v1::JobStatus::RUNNING);
  EXPECT_EQ(states.at(4), v1::JobStatus::QUEUED);  // not started: no film held for it
  for (const v1::Task& t : r.tasks()) ASSERT_TRUE(c->submit_result(render_task(t, w)).accepted());
  drain(w);
  for (int n : {1, 2, 3, 4}) EXPECT_TRUE(frame_is_local(id, n)) << n;
}

// A sequence's next frame is made ahead, films and all (at submit, then on the reaper's
// tick): those films count against --max-live-pixels. They did not, so a client could hold
// a prepared 8K film per sequence, up to its job limit, past any memory.
TEST_F(SequenceTest, APreparedFrameCountsAgainstTheLivePixels) {
  CoordinatorOptions o = options();
  o.max_live_pixels = live_pixels_of(job_settings());  // one frame's films
  c.reset();                                           // (the old one lets the data folder go first)
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(&t));
  const std::string id = c->submit(sequence({1, 2}));
  try {
    c->submit(sequence({1, 2}));
    ADD_FAILURE() << "a second prepared frame passed the limit";
  } catch (const RequestError& e) {
    EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
    EXPECT_NE(std::string(e.what()).find("(--max-live-pixels)"), std::string::npos) << e.what();
  }
  // The first frame starts from its prepared films; the second is neither started nor
  // made while the first holds the limit, and starts once the first is done.
  const uint64_t w = worker();
  const v1::GetTaskResponse r = c->get_task(w, 100);
  for (const v1::Task& task : r.tasks()) EXPECT_EQ(task.job_id(), id + "-f1");
  c->expire_leases();  // the reaper's tick: nothing to prepare within the limit
  EXPECT_EQ(frame_states(id).at(2), v1::JobStatus::QUEUED);
  for (const v1::Task& task : r.tasks()) ASSERT_TRUE(c->submit_result(render_task(task, w)).accepted());
  drain(w);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int n : {1, 2}) EXPECT_TRUE(frame_is_local(id, n)) << n;
}

TEST_F(SequenceTest, CancelKeepsFinishedFrames) {
  const std::string id = c->submit(sequence({1, 2, 3}));
  const uint64_t w = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());  // a tile of frame 2
  const v1::JobStatus st = c->cancel(id);
  EXPECT_EQ(st.state(), v1::JobStatus::CANCELLED);
  const auto states = frame_states(id);
  EXPECT_EQ(states.at(1), v1::JobStatus::DONE);
  EXPECT_EQ(states.at(2), v1::JobStatus::CANCELLED);
  EXPECT_EQ(states.at(3), v1::JobStatus::CANCELLED);  // never started
  EXPECT_EQ(c->get_task(w).tasks_size(), 0);
  EXPECT_TRUE(frame_is_local(id, 1));
  EXPECT_GT(c->image(id, true, false, 2).exr().size(), 0u);  // what frame 2 had is kept
  EXPECT_THROW(c->image(id, true, false, 3), RequestError);
  // After a restart, as it was.
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(frame_states(id), states);
  EXPECT_TRUE(frame_is_local(id, 1));
}

// Found by audit: /api/jobs/<id> listed every frame of a sequence (100,000 frames: 12 MB
// of JSON each second for each open live page). Frames come a page at a time, with the
// frame a viewer shows (the one rendering, else the last started) named whatever the page.
TEST_F(SequenceTest, FramesComeAPageAtATimeWithTheFrameBeingRenderedNamed) {
  const std::string id = c->submit(sequence({1, 2, 3, 4, 5}));
  const uint64_t w = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());  // a tile of frame 2
  v1::JobStatus st = c->status(id, true, {}, FrameRange{2, 2});
  ASSERT_EQ(st.frames_size(), 2);
  EXPECT_EQ(st.frames(0).frame(), 3);
  EXPECT_EQ(st.frames(1).frame(), 4);
  EXPECT_EQ(st.frames_total(), 5u);
  EXPECT_EQ(st.current_frame_job(), id + "-f2");  // rendering, though not on the page
  const nlohmann::json page = nlohmann::json::parse(job_status_json(st, 0, 2));
  EXPECT_EQ(page["frames_from"], 2);
  EXPECT_EQ(page["frames_next"], 4);
  EXPECT_EQ(page["current_frame_job"], id + "-f2");
  st = c->status(id, true, {}, FrameRange{4, 99});
  ASSERT_EQ(st.frames_size(), 1);
  EXPECT_EQ(nlohmann::json::parse(job_status_json(st, 0, 4))["frames_next"], nullptr);
  // Ended and archived: the same pages from its stored status; the last frame started shown.
  c->cancel(id);
  restart(c, options(), &t);
  st = c->status(id, true, {}, FrameRange{0, 1});
  ASSERT_EQ(st.frames_size(), 1);
  EXPECT_EQ(st.frames(0).frame(), 1);
  EXPECT_EQ(st.current_frame_job(), id + "-f2");
  EXPECT_EQ(c->status(id, true, {}, FrameRange{7, 1}).frames_size(), 0);
  EXPECT_EQ(c->status(id, false).frames_size(), 5);  // GetJob: every frame
  // A list (/api/status) counts them from the stored summary without reading them.
  const std::vector<v1::JobStatus> recent = c->recent(10);
  ASSERT_EQ(recent.size(), 1u);
  EXPECT_EQ(recent[0].frames_size(), 0);
  EXPECT_EQ(recent[0].frames_total(), 5u);
  EXPECT_EQ(recent[0].frames_done(), 1u);
  EXPECT_EQ(recent[0].state(), v1::JobStatus::CANCELLED);
}

TEST_F(SequenceTest, ARestartedCoordinatorGoesOnWithASequenceBitForBit) {
  const std::string id = c->submit(sequence({1, 2, 3}), "someone");
  const uint64_t w = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  for (int k = 0; k < 4; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;  // the next merge writes frame 2's checkpoint
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t at_checkpoint = c->status(id, false).samples_done();
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());  // lost in the crash

  restart(c, options(), &t);
  v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(st.owner(), "someone");
  EXPECT_EQ(st.samples_done(), at_checkpoint);
  EXPECT_EQ(frame_states(id).at(1), v1::JobStatus::DONE);
  EXPECT_EQ(frame_states(id).at(3), v1::JobStatus::QUEUED);
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int n : {1, 2, 3}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int n : {1, 2, 3}) EXPECT_TRUE(frame_is_local(id, n)) << n;
  EXPECT_FALSE(fs::is_empty(dir + "/scenes"));  // the ended sequence's scene stays until it is deleted
  c->remove(id);
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));
  EXPECT_FALSE(fs::exists(dir + "/jobs/" + id + "-f1"));
}

// Found by audit: a restart read every finished frame's film and wrote its image again (in
// case the crash came between the two), all held at once, and a finished frame kept its
// film on disk in its checkpoint until the sequence was archived or deleted. A finished
// frame's checkpoint is now written after its image, without the film, and a restart reads
// a frame whose image holds every pass (its frame_passes attribute) without its film and
// leaves it be. One whose image is gone is rendered again, the same bits.
TEST_F(SequenceTest, AFinishedFrameKeepsNoFilmAndARestartLeavesItsImageBe) {
  const std::string id = c->submit(sequence({1, 2, 3}));
  const uint64_t w = worker();
  while (frame_states(id).at(2) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::RUNNING);  // frame 3 to go
  for (const char* f : {"-f1", "-f2"}) {  // the progress alone: a few bytes a tile, where the film is 62 KB
    const std::string checkpoint = image_path(id + f, "checkpoint");
    for (int i = 0; i < 500 && !fs::exists(checkpoint); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    EXPECT_LT(fs::file_size(checkpoint), 1024u) << f;
  }
  const std::string kept = image_path(id + "-f1", "image.exr"), lost = image_path(id + "-f2", "image.exr");
  ASSERT_TRUE(fs::exists(kept));
  const auto written = fs::last_write_time(kept);
  fs::remove(lost);
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // (a file written again would have a later time)
  restart(c, options(), &t);
  EXPECT_EQ(frame_states(id).at(1), v1::JobStatus::DONE);
  EXPECT_NE(frame_states(id).at(2), v1::JobStatus::DONE);  // no film to write it from: rendered again
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(fs::last_write_time(kept), written);
  for (int n : {1, 2, 3}) EXPECT_TRUE(frame_is_local(id, n)) << n;
}

// A restart can bring a sequence back with a gap: frames 1 and 3 have checkpoints, frame 2
// (started, but killed before its first checkpoint) has none. Its load is then the two
// restored frames' samples left plus one whole frame, not two: the admission limit
// double-counted frame 3 (a bug of the three load formulas that disagreed).
TEST_F(SequenceTest, ASequenceRestoredWithAGapInItsFramesIsCountedOnce) {
  const std::string id = c->submit(sequence({1, 2, 3}), "someone");
  const uint64_t w = worker();
  const v1::GetTaskResponse r = c->get_task(w, 27);  // every frame's first pass: all three start
  ASSERT_EQ(r.tasks_size(), 27);
  std::set<std::string> merged;
  for (const v1::Task& task : r.tasks()) {
    if (merged.insert(task.job_id()).second) {
      ASSERT_TRUE(c->submit_result(render_task(task, w)).accepted());
    }
  }
  ASSERT_EQ(merged.size(), 3u);
  c->checkpoint_all();
  fs::remove(dir + "/jobs/" + id + "-f2/checkpoint");  // frame 2 never reached its first checkpoint
  restart(c, options(), &t);
  EXPECT_EQ(frame_states(id).at(2), v1::JobStatus::QUEUED);
  const uint64_t frame = 48 * 36 * 10, tile_pass = 16 * 16 * 4;
  const uint64_t left = 2 * (frame - tile_pass) + frame;
  EXPECT_EQ(c->queue().samples_remaining, left);
  // A still of one frame's samples fits exactly under a limit of what is left plus it.
  CoordinatorOptions o = options();
  o.max_queued_samples_per_client = left + frame;
  restart(c, o, &t);
  EXPECT_NO_THROW(c->submit(request(job_settings()), "someone"));
  EXPECT_THROW(c->submit(request(job_settings()), "someone"), RequestError);
}

TEST_F(SequenceTest, AFrameFailingOnTwoWorkersFailsTheSequenceAndKeepsTheFinishedFrames) {
  const std::string id = c->submit(sequence({1, 2}));
  const uint64_t a = worker(), b = worker();
  while (frame_states(id).at(1) != v1::JobStatus::DONE)
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(a).tasks(0), a)).accepted());
  c->release(a, c->get_task(a).tasks(0).task_id(), "scene does not load here");
  // While it waits for another worker the sequence says why, naming the frame (as a still
  // does: a watcher prints it).
  EXPECT_EQ(c->status(id, false).error(), "frame 2: a task failed on registration " + std::to_string(a) +
                                              ": scene does not load here (the job fails once tasks fail on 2 "
                                              "workers; 1 so far; that worker is not given its tasks for 30 s)");
  c->release(b, c->get_task(b).tasks(0).task_id(), "scene does not load here");
  const v1::JobStatus st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::FAILED);
  EXPECT_NE(st.error().find("frame 2"), std::string::npos) << st.error();
  EXPECT_TRUE(frame_is_local(id, 1));
}

// A submit the job database cannot record is refused (a still and a sequence alike), its
// scene is not kept, and nothing is left running.
TEST_F(SequenceTest, ASubmitTheDatabaseCannotRecordIsRefused) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir + "/coordinator.db").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "DROP TABLE jobs", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  for (const v1::SubmitJobRequest& r : {request(job_settings()), sequence({1, 2})}) {
    try {
      c->submit(r);
      ADD_FAILURE() << "accepted";
    } catch (const RequestError& e) {
      EXPECT_EQ(e.code(), RequestError::Code::kResourceExhausted);
      EXPECT_NE(std::string(e.what()).find("the coordinator cannot record the job"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(c->list().empty());
  EXPECT_EQ(c->counters().jobs_refused, 2u);
  // Its scene is not served; with no database to ask whether another job names it, its
  // files stay until the next start prunes what no job names.
  EXPECT_THROW(c->scene(bundle_hash(request(job_settings()).main_file(), request(job_settings()).files())),
               RequestError);
  restart(c, options(), &t);
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));
}

TEST_F(SequenceTest, BadFrameListsAreRefusedNamingTheProblem) {
  auto refused = [&](const v1::SubmitJobRequest& r, const std::string& part) {
    try {
      c->submit(r);
      ADD_FAILURE() << "accepted";
    } catch (const RequestError& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  refused(sequence({1, 2, 1}), "frame 1 given twice");
  refused(sequence({1, 2000000}), "frame 2000000 out of range");
  v1::SubmitJobRequest r = sequence({1, 2});
  r.mutable_settings()->set_frame(4);
  refused(r, "frame number");
  EXPECT_TRUE(c->list().empty());
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: a restart swept half-written files only of frames whose checkpoint it
// found (a crash cutting a frame's first checkpoint short left a film's worth of
// checkpoint.tmp until the job was deleted), and never a denoised image's noisy step.
TEST_F(SequenceTest, ARestartSweepsHalfWrittenFilesOfEveryFrame) {
  const std::string id = c->submit(sequence({1, 2, 3}));
  c.reset();
  std::vector<std::string> strays;
  for (const int f : {1, 2, 3}) {
    const std::string folder = dir + "/jobs/" + Sequence::frame_id(id, f);
    fs::create_directories(folder);
    for (const char* name : {"checkpoint.tmp", "image.noisy.exr", "image.noisy.exr.tmp"}) {
      strays.push_back(folder + "/" + name);
      std::ofstream(strays.back()) << "half";
    }
  }
  c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t));
  for (const std::string& p : strays) EXPECT_FALSE(fs::exists(p)) << p;
  drain(worker());
  EXPECT_TRUE(frame_is_local(id, 2));
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: every task of every frame carried the sequence's whole camera path (up to
// 1 MiB: a 1080p frame's 8,000 tasks 4.5 GB of it). A frame's tasks now carry one key, what
// that frame takes from the path, and render the frame as the whole path does locally.
TEST_F(SequenceTest, AFramesTasksCarryOnlyItsCameraFromAPath) {
  RenderSettings s = job_settings();
  std::string keys = R"({"keys": [)";
  for (int k = 0; k <= 60; ++k)
    keys += (k ? "," : "") + std::string(R"({"frame": )") + std::to_string(k) + R"(, "eye": [)" +
            std::to_string(0.02 * k) + R"(, 1, 4.3], "fov": )" + std::to_string(40 + 0.1 * k) + "}";
  keys += "]}";
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(keys));
  v1::SubmitJobRequest r = request(s);
  for (int f : {3, 17}) r.add_frames(f);
  const std::string id = c->submit(r);
  const uint64_t w = worker();
  int tasks = 0;
  for (int guard = 0; guard < 1000; ++guard) {
    const v1::GetTaskResponse got = c->get_task(w);
    if (got.tasks_size() == 0) break;
    const v1::Task& task = got.tasks(0);
    const CameraPath carried = CameraPath::parse(task.settings().camera_path());
    ASSERT_EQ(carried.keys.size(), 1u);
    EXPECT_EQ(carried.keys[0].frame, task.settings().frame());
    ++tasks;
    ASSERT_TRUE(c->submit_result(render_task(task, w)).accepted());
  }
  EXPECT_EQ(tasks, 2 * 9 * 3);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  for (int f : {3, 17}) {
    const std::string path = dir + "/frame" + std::to_string(f) + ".exr";
    std::ofstream(path, std::ios::binary) << c->image(id, true, false, f).exr();
    RenderSettings local_settings = s;  // the whole path, as tessera render has it
    local_settings.frame = f;
    EXPECT_TRUE(same_film_as_exr(local(local_settings), read_exr(path))) << f;
  }
}

// A still's tasks too (a path and --frame, no sequence).
TEST_F(SequenceTest, AStillsTasksCarryOnlyItsCameraFromAPath) {
  RenderSettings s = job_settings();
  s.frame = 2;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 0, "eye": [0, 1, 4.5]}, {"frame": 1, "eye": [0.2, 1, 4.4]},
                   {"frame": 5, "eye": [0.5, 1.1, 4]}]})"));
  const std::string id = c->submit(request(s));
  const uint64_t w = worker();
  const v1::GetTaskResponse got = c->get_task(w);
  ASSERT_EQ(got.tasks_size(), 1);
  EXPECT_EQ(CameraPath::parse(got.tasks(0).settings().camera_path()).keys.size(), 1u);
  ASSERT_TRUE(c->submit_result(render_task(got.tasks(0), w)).accepted());
  drain(w);
  const std::string path = dir + "/still.exr";
  std::ofstream(path, std::ios::binary) << c->image(id, true, false).exr();
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(path)));
}

}  // namespace
}  // namespace tessera
