// The coordinator made again on the same data folder, as after kill -9.
#include <sqlite3.h>

#include "server/data_marker.h"
#include "tests/server/coordinator_fixture.h"

namespace tessera {
namespace {

// ---- crash safety: a coordinator made again on the same data folder ----------------------

TEST_F(CoordinatorTest, ARestartedCoordinatorGoesOnWithEveryJobInItsState) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string done = c->submit(request(s));
  drain(w);
  const std::string cancelled = c->submit(request(s));
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  c->cancel(cancelled);
  const std::string live = c->submit(request(s));
  const std::string waiting = c->submit(request(s), "someone");
  for (int k = 0; k < 5; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;  // past checkpoint_seconds: the next merge writes a checkpoint
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t at_checkpoint = c->status(live, false).samples_done();
  for (int k = 0; k < 2; ++k)  // merged after the checkpoint: lost with the coordinator
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const v1::Task in_flight = c->get_task(w).tasks(0);
  const std::vector<v1::JobStatus> before = c->list();

  restart(c, options(), &t);
  const std::vector<v1::JobStatus> after = c->list();
  ASSERT_EQ(after.size(), before.size());
  for (size_t i = 0; i < after.size(); ++i) {
    EXPECT_EQ(after[i].id(), before[i].id());
    EXPECT_EQ(after[i].name(), before[i].name());
    EXPECT_EQ(after[i].owner(), before[i].owner());
    EXPECT_EQ(after[i].state(), before[i].state()) << i;
  }
  EXPECT_EQ(c->status(done, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(done, false).samples_done(), c->status(done, false).samples_total());
  EXPECT_EQ(c->status(cancelled, false).state(), v1::JobStatus::CANCELLED);
  EXPECT_EQ(c->status(live, false).state(), v1::JobStatus::RUNNING);
  EXPECT_EQ(c->status(live, false).samples_done(), at_checkpoint);
  EXPECT_EQ(c->status(waiting, false).state(), v1::JobStatus::QUEUED);
  EXPECT_EQ(c->counters().jobs_restored, before.size());
  // The old run's worker must register again, and its task of the old run counts no more.
  EXPECT_THROW(c->get_task(w), RequestError);
  EXPECT_FALSE(c->submit_result(render_task(in_flight, w)).accepted());
  const uint64_t w2 = worker();
  drain(w2);
  for (const std::string& id : {done, live, waiting}) {
    EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE) << id;
    EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr")))) << id;
    EXPECT_GT(c->image(id, true, false).exr().size(), 0u);
  }
  EXPECT_GT(c->image(cancelled, true, false).exr().size(), 0u);  // what was rendered stays
  restart(c, options(), &t);                                     // and once more, with everything ended
  for (const std::string& id : {done, live, waiting}) EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_THROW(c->cancel(waiting, "another", false), RequestError);  // owners are kept
  const std::string next = c->submit(request(s));
  EXPECT_EQ(c->list().back().id(), next);  // after the restored ones
}

// Found by audit: a DONE job whose final image could not be written (a full disk at its
// end; in memory the write is retried on fetch) came back from a restart as written. The
// first fetch served what was on disk as final, and the archive deleted the checkpoint,
// the film's only whole copy. Now its film is read back and the image written again.
TEST_F(CoordinatorTest, ADoneJobWhoseFinalImageWasNotWrittenGetsItAfterARestart) {
  const RenderSettings s = job_settings();
  const std::string id = c->submit(request(s));
  const std::string blocker = image_path(id, "image.exr.tmp");
  fs::create_directories(blocker + "/x");  // every image write fails; checkpoints do not
  drain(worker());
  v1::JobStatus st = c->status(id, false);
  ASSERT_EQ(st.state(), v1::JobStatus::DONE);
  ASSERT_NE(st.error().find("image not written"), std::string::npos) << st.error();
  fs::remove_all(blocker);
  restart(c, options(), &t);
  st = c->status(id, false);
  EXPECT_EQ(st.state(), v1::JobStatus::DONE);
  EXPECT_EQ(st.samples_done(), st.samples_total());
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  const auto fetched = c->image(id, true, false);
  EXPECT_TRUE(fetched.final());
  // And once more: now that the image is whole, the job is taken as written.
  restart(c, options(), &t);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
}

// Found by audit: a row whose settings could not be read stopped the whole start (one row
// took the farm down), and one whose settings read but were refused was skipped while the
// same start deleted its checkpoint, image and scene. Neither is taken up now; the start
// goes on and their files stay.
TEST_F(CoordinatorTest, AnUnreadableJobRowNeitherStopsTheStartNorLosesItsFiles) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string garbled = c->submit(request(s)), refused = c->submit(request(s)), fine = c->submit(request(s));
  const auto checkpointed = [&](const std::string& id) { return fs::exists(dir + "/jobs/" + id + "/checkpoint"); };
  for (int k = 0; k < 400 && !(checkpointed(garbled) && checkpointed(refused)); ++k) {
    t += 6;  // past checkpoint_seconds: each merge writes a checkpoint
    ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  }
  ASSERT_TRUE(checkpointed(refused));
  c.reset();
  ASSERT_TRUE(fs::exists(dir + "/jobs/" + garbled + "/checkpoint"));
  v1::RenderSettings bad = to_proto(s);
  bad.set_spp(0);  // a message, but settings validate() refuses
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir + "/coordinator.db").c_str(), &db), SQLITE_OK);
  const std::string sql = "UPDATE jobs SET settings = x'ffff' WHERE id = '" + garbled + "'";
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE jobs SET settings = ?1 WHERE id = ?2", -1, &st, nullptr), SQLITE_OK);
  const std::string bytes = bad.SerializeAsString();
  sqlite3_bind_blob(st, 1, bytes.data(), int(bytes.size()), SQLITE_TRANSIENT);
  sqlite3_bind_text(st, 2, refused.c_str(), -1, SQLITE_TRANSIENT);
  ASSERT_EQ(sqlite3_step(st), SQLITE_DONE);
  sqlite3_finalize(st);
  sqlite3_close(db);
  ASSERT_NO_THROW(c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t)));
  std::vector<std::string> listed;
  for (const v1::JobStatus& j : c->list()) listed.push_back(j.id());
  EXPECT_EQ(listed, std::vector<std::string>{fine});
  for (const std::string& id : {garbled, refused}) EXPECT_TRUE(fs::exists(dir + "/jobs/" + id)) << id;
  EXPECT_FALSE(fs::is_empty(dir + "/scenes"));
  drain(worker());  // the rest goes on
  EXPECT_EQ(c->status(fine, false).state(), v1::JobStatus::DONE);
}

// Found by audit: a checkpoint or scene manifest that exists but cannot be read (its
// permissions after a restore from backup, an I/O error) was taken as damaged or missing: the
// job started over (overwriting the checkpoint) or failed for good. The start stops instead,
// naming the file and why. (A link to itself: unreadable even to root, as CI runs.)
TEST_F(CoordinatorTest, AnUnreadableCheckpointOrManifestStopsTheStartNamingIt) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string id = c->submit(request(s));
  t += 6;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  c.reset();
  const fs::path checkpoint = dir + "/jobs/" + id + "/checkpoint";
  ASSERT_TRUE(fs::exists(checkpoint));
  // The start's refusal, with `file` a link to itself (and back as it was after).
  const auto refused_start = [&](const fs::path& file) -> std::string {
    fs::rename(file, file.string() + ".kept");
    fs::create_symlink(file, file);
    std::string why = "(started)";
    try {
      c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t));
    } catch (const DataFolderError& e) {
      why = e.what();
    }
    c.reset();  // (one that started holds the data folder)
    fs::remove(file);
    fs::rename(file.string() + ".kept", file);
    return why;
  };
  std::string why = refused_start(checkpoint);
  EXPECT_NE(why.find(checkpoint.string() + ": cannot read the checkpoint: Too many levels"), std::string::npos) << why;
  fs::path manifest;
  for (const auto& e : fs::directory_iterator(dir + "/scenes"))
    if (fs::exists(e.path() / "manifest")) manifest = e.path() / "manifest";
  ASSERT_FALSE(manifest.empty());
  why = refused_start(manifest);
  EXPECT_NE(why.find(manifest.string() + ": cannot read the scene's manifest"), std::string::npos) << why;
  c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t));  // mended: it goes on
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::RUNNING);
  EXPECT_GT(c->status(id, false).samples_done(), 0u);
}

// A crash after a job's last merge but before its end is on disk (its final checkpoint
// not yet renamed into place; here no checkpoint ever is): the restarted coordinator still
// has the scene and renders what the checkpoints lack. (The scene used to be deleted at
// the end in memory, and such a job came back FAILED, its scene lost.) The same for a
// sequence.
TEST_F(CoordinatorTest, ACrashBeforeTheEndIsRecordedKeepsTheScene) {
  const RenderSettings s = job_settings();
  CoordinatorOptions o = options();
  o.before_checkpoint_rename = [] { throw std::runtime_error("simulated crash before the rename"); };
  restart(c, o, &t);
  const std::string id = c->submit(request(s));
  v1::SubmitJobRequest seq = request(s);
  seq.add_frames(1);
  seq.add_frames(2);
  const std::string sequence = c->submit(seq);
  drain(worker());
  // Done in memory, not on disk: clients are not told it ended (a restart takes it up again).
  ASSERT_EQ(c->status(sequence, false).state(), v1::JobStatus::RUNNING);
  ASSERT_EQ(c->status(id, false).state(), v1::JobStatus::RUNNING);
  EXPECT_FALSE(c->image(id, true, false).final());
  restart(c, options(), &t);
  for (const std::string& j : {id, sequence}) EXPECT_NE(c->status(j, false).state(), v1::JobStatus::FAILED) << j;
  drain(worker());
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(sequence, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(id, "image.exr"))));
  // Recorded now: another restart finds both ended; their scene stays until they are deleted.
  restart(c, options(), &t);
  EXPECT_EQ(c->status(id, false).state(), v1::JobStatus::DONE);
  EXPECT_EQ(c->status(sequence, false).state(), v1::JobStatus::DONE);
  EXPECT_FALSE(fs::is_empty(dir + "/scenes"));
  c->remove(id);
  c->remove(sequence);
  EXPECT_TRUE(fs::is_empty(dir + "/scenes"));
}

TEST_F(CoordinatorTest, ADamagedCheckpointRendersTheJobAgainAndAMissingSceneFailsIt) {
  const RenderSettings s = job_settings();
  const uint64_t w = worker();
  const std::string a = c->submit(request(s));
  RenderSettings other = s;
  other.seed = 9;  // a second job, with no checkpoint yet
  const std::string b = c->submit(request(other));
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  t += 6;
  ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const std::string cp = dir + "/jobs/" + a + "/checkpoint";
  ASSERT_TRUE(fs::exists(cp));
  {  // one byte flipped in the film
    std::string bytes = read_file_bytes(cp);
    bytes[bytes.size() / 2] ^= 0x10;
    write_file_atomic(cp, bytes);
  }
  restart(c, options(), &t);
  EXPECT_EQ(c->status(a, false).samples_done(), 0u);  // rendered again, from the start
  const uint64_t w2 = worker();
  drain(w2);
  EXPECT_EQ(c->status(a, false).state(), v1::JobStatus::DONE);
  EXPECT_TRUE(same_film_as_exr(local(s), read_exr(image_path(a, "image.exr"))));
  EXPECT_TRUE(same_film_as_exr(local(other), read_exr(image_path(b, "image.exr"))));

  // A live job whose scene is gone from the data folder fails, saying why, without a path.
  const std::string c1 = c->submit(request(s));
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "scenes")) fs::remove_all(e.path());
  restart(c, options(), &t);
  const v1::JobStatus st = c->status(c1, false);
  EXPECT_EQ(st.state(), v1::JobStatus::FAILED);
  EXPECT_NE(st.error().find("scene is missing"), std::string::npos) << st.error();
  EXPECT_EQ(st.error().find(dir), std::string::npos) << st.error();
  restart(c, options(), &t);
  EXPECT_EQ(c->status(c1, false).state(), v1::JobStatus::FAILED);  // recorded
}

// Scenes no job names (a deleted job's, a submit the crash cut short) go at a restart; an
// ended job's scene stays, for a requeue, until the job is deleted.
TEST_F(CoordinatorTest, ScenesNoJobNamesAreNotKeptAcrossARestart) {
  const v1::SubmitJobRequest req = request(job_settings());
  const std::string a = c->submit(req);
  c->cancel(a);
  fs::create_directories(fs::path(dir) / "scenes" / "0123.staging-7");  // a crash mid-submit
  std::ofstream(fs::path(dir) / "scenes" / "feedfeedfeedfeedfeedfeedfeedfeed.bundle") << "x";
  restart(c, options(), &t);
  std::set<std::string> left;
  for (const auto& e : fs::directory_iterator(fs::path(dir) / "scenes")) left.insert(e.path().filename().string());
  EXPECT_EQ(left, std::set<std::string>{bundle_hash(req.main_file(), req.files())});
  c->remove(a);
  EXPECT_TRUE(fs::is_empty(fs::path(dir) / "scenes"));
}

TEST_F(CoordinatorTest, AStoppedCoordinatorSavesEveryResultItMerged) {
  const std::string a = c->submit(request(job_settings()));
  const uint64_t w = worker();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(c->submit_result(render_task(c->get_task(w).tasks(0), w)).accepted());
  const uint64_t merged = c->status(a, false).samples_done();
  c->checkpoint_all();  // what main does on SIGTERM
  restart(c, options(), &t);
  EXPECT_EQ(c->status(a, false).samples_done(), merged);
}

}  // namespace
}  // namespace tessera
