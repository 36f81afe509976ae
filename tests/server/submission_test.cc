// A submit made ready outside the lock: its scene checked as a worker will load it, its
// job (or sequence, first frame prepared) made, and its row recorded before the client
// hears of it. A SceneStore in a temporary folder and a MemoryJobStore.
#include "server/submission.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "scene_bundle.h"
#include "tests/core/test_paths.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::has;
using testing::refusal;
using Code = RequestError::Code;

class SubmissionTest : public ::testing::Test {
 protected:
  const fs::path dir = fs::temp_directory_path() / ("tessera_submission_" + std::to_string(::getpid()));
  SceneStore scenes{(dir / "scenes").string()};
  MemoryJobStore store;

  void TearDown() override { fs::remove_all(dir); }

  static v1::SubmitJobRequest request(const std::vector<int>& frames = {}) {
    v1::SubmitJobRequest r;
    r.set_version(kProtocolVersion);
    std::string main;
    pack_scene(tessera::testing::source_path("scenes/cornell-spheres.dae"), &main, r.mutable_files());
    r.set_main_file(main);
    r.set_priority(2);
    *r.mutable_settings() = to_proto(tessera::testing::small_settings());
    for (int f : frames) r.add_frames(f);
    return r;
  }
  Submission prepare(const v1::SubmitJobRequest& r, JobStore& into) {
    JobMeta meta;
    meta.id = "00000000000000ab";
    meta.seq = 7;
    meta.owner = "ann";
    return prepare_submission(r, admit(r), meta, scenes, into, dir.string());
  }
  Submission prepare(const v1::SubmitJobRequest& r) { return prepare(r, store); }
  size_t files_kept() const {  // in the scene folder
    size_t n = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir / "scenes")) ++n;
    return n;
  }
};

TEST_F(SubmissionTest, AGoodSceneGivesAJobAndARecordedRow) {
  const v1::SubmitJobRequest r = request();
  const Submission sub = prepare(r);
  ASSERT_NE(sub.job, nullptr);
  EXPECT_EQ(sub.sequence, nullptr);
  const JobMeta& m = sub.job->meta;
  EXPECT_EQ(m.id, "00000000000000ab");
  EXPECT_EQ(m.owner, "ann");
  EXPECT_EQ(m.scene_hash, bundle_hash(r.main_file(), r.files()));
  EXPECT_EQ(m.name, r.main_file());  // no name given: the scene file's
  EXPECT_EQ(m.priority, 2);
  EXPECT_EQ(m.scene_bytes, bundle_bytes(r.files()));
  EXPECT_EQ(sub.job->state(), v1::JobStatus::QUEUED);
  EXPECT_EQ(sub.job->plan.tiles().size(), testing::kTiles);
  EXPECT_EQ(scenes.manifest(m.scene_hash).main_file(), r.main_file());  // kept for workers
  const std::vector<StoredJob> rows = store.jobs();
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].meta.id, m.id);
  EXPECT_EQ(rows[0].meta.seq, 7u);
  EXPECT_EQ(rows[0].meta.scene_hash, m.scene_hash);
  EXPECT_EQ(rows[0].meta.settings.spp(), 10u);
  EXPECT_TRUE(rows[0].frames.empty());
}

TEST_F(SubmissionTest, ASequenceComesWithItsFirstFramePrepared) {
  const Submission sub = prepare(request({8, 9}));
  ASSERT_NE(sub.sequence, nullptr);
  EXPECT_EQ(sub.job, nullptr);
  EXPECT_EQ(sub.sequence->frames, (std::vector<int>{8, 9}));
  ASSERT_NE(sub.sequence->prepared, nullptr);
  EXPECT_EQ(sub.sequence->prepared->frame_index, 0u);
  EXPECT_EQ(sub.sequence->prepared->plan.settings().frame, 8);
  ASSERT_EQ(store.jobs().size(), 1u);
  EXPECT_EQ(store.jobs()[0].frames, (std::vector<int>{8, 9}));
}

TEST_F(SubmissionTest, ABadSceneIsRefusedWithTheLoadersMessageAndLeavesNothing) {
  v1::SubmitJobRequest r = request();
  r.clear_files();
  v1::SceneFile* f = r.add_files();
  f->set_path("broken.dae");
  f->set_content("<COLLADA><library_geometries><geometry>");
  r.set_main_file("broken.dae");
  const std::string why = refusal([&] { prepare(r); }, Code::kInvalidArgument);
  EXPECT_TRUE(has(why, "broken.dae")) << why;  // the file as the user knows it
  EXPECT_TRUE(store.jobs().empty());
  EXPECT_EQ(files_kept(), 0u);
}

TEST_F(SubmissionTest, SettingsTheSceneCannotHonourAreRefused) {
  v1::SubmitJobRequest r = request();
  r.mutable_settings()->set_animation("walk");
  const std::string why = refusal([&] { prepare(r); }, Code::kInvalidArgument);
  EXPECT_EQ(why, "--animation: the scene has no animations");
  EXPECT_TRUE(store.jobs().empty());
  EXPECT_EQ(files_kept(), 0u);
}

// The same bytes submitted again are not stored twice, but each job's settings are checked
// against them: a second job asking for an animation the scene lacks is refused, and the
// first job's use of the scene stays.
TEST_F(SubmissionTest, SettingsAreCheckedAgainstAKeptSceneToo) {
  const v1::SubmitJobRequest good = request();
  prepare(good);
  const size_t kept = files_kept();
  v1::SubmitJobRequest bad = request();
  bad.mutable_settings()->set_animation("walk");
  const std::string why = refusal([&] { prepare(bad); }, Code::kInvalidArgument);
  EXPECT_EQ(why, "--animation: the scene has no animations");
  EXPECT_EQ(store.jobs().size(), 1u);
  EXPECT_EQ(files_kept(), kept);
  const std::string hash = bundle_hash(good.main_file(), good.files());
  EXPECT_NO_THROW(scenes.manifest(hash));
  scenes.release(hash);  // the first job's use, the only one: the refused job's was given back
  EXPECT_THROW(scenes.manifest(hash), std::out_of_range);
}

// Light paths' splats travel with tasks' results (docs/light-tracing.md): every mode is
// admitted. Auto is decided when the scene is loaded at submit (here: on, for the glass and
// mirror spheres), so that every result of its frames must carry splats; a scene whose
// bytes are kept already (every submit here after the first) is checked and decided from
// the kept copy.
TEST_F(SubmissionTest, LightTracingModesAreAdmittedAndAutoIsDecidedFromTheScene) {
  const std::pair<uint32_t, uint32_t> modes[] = {{2, 1}, {1, 1}, {0, 0}, {2, 1}};  // asked, kept
  for (const auto& [mode, kept] : modes) {
    v1::SubmitJobRequest r = request();
    r.mutable_settings()->set_light_tracer(mode);
    EXPECT_EQ(admit(r).settings.light_tracer, RenderSettings::LightTracer(mode));  // the wire carries it
    MemoryJobStore fresh;
    const Submission sub = prepare(r, fresh);
    ASSERT_NE(sub.job, nullptr);
    EXPECT_EQ(sub.job->plan.settings().light_tracer, RenderSettings::LightTracer(kept)) << mode;
    ASSERT_EQ(fresh.jobs().size(), 1u);
    EXPECT_EQ(fresh.jobs()[0].meta.settings.light_tracer(), kept) << mode;
  }
}

TEST_F(SubmissionTest, AStoreThatCannotRecordTheJobRefusesItAndReleasesTheScene) {
  const v1::SubmitJobRequest r = request();
  store.fail_writes = true;
  const std::string why = refusal([&] { prepare(r); }, Code::kResourceExhausted);
  EXPECT_EQ(why, "the coordinator cannot record the job: job database: disk I/O error (a test's)");
  EXPECT_THROW(scenes.manifest(bundle_hash(r.main_file(), r.files())), std::out_of_range);
  EXPECT_EQ(files_kept(), 0u);
}

TEST_F(SubmissionTest, ASceneAnotherJobUsesStaysWhenASubmitIsRefused) {
  const v1::SubmitJobRequest r = request();
  prepare(r);
  store.fail_writes = true;
  refusal([&] { prepare(r); }, Code::kResourceExhausted);
  EXPECT_NO_THROW(scenes.manifest(bundle_hash(r.main_file(), r.files())));
}

TEST_F(SubmissionTest, TheDataFolderIsHiddenFromTheRefusal) {
  struct FullDisk : MemoryJobStore {
    std::string at;
    void add(const StoredJob&) override { throw std::runtime_error("job database: cannot write " + at + "/x.db"); }
  } full;
  full.at = dir.string();
  const std::string why = refusal([&] { prepare(request(), full); }, Code::kResourceExhausted);
  EXPECT_EQ(why, "the coordinator cannot record the job: job database: cannot write <data>/x.db");
}

}  // namespace
}  // namespace tessera
