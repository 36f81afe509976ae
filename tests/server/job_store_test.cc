// The job database and film checkpoints: what a restarted coordinator reads back.
#include "server/job_store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>
#include <zstd.h>

#include <cstddef>
#include <cstring>
#include <filesystem>
#include <limits>
#include <vector>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include "proto/wire.h"
#include "server/checkpoint.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

struct Saved {
  PlanState state;
  Film film{Rect{2, 3, 5, 4}};
};

// `bytes` with the checksum a checkpoint ends with: older versions made from newer files.
std::string with_checksum(std::string bytes) {
  const uint64_t sum = XXH64(bytes.data(), bytes.size(), 0);
  bytes.append(reinterpret_cast<const char*>(&sum), 8);
  return bytes;
}

Saved sample() {
  Saved s;
  s.state.progress = {{2, false, 0.25f}, {3, true, 0.125f}};
  s.state.active.assign(20, 1);
  s.state.active[7] = 0;
  s.state.samples_merged = 1234;
  s.state.merges = 5;
  s.state.work_done = 0.1;  // not exact in binary: must come back bit for bit anyway
  s.state.work_total = 3e9;
  for (size_t i = 0; i < 20; ++i) {
    PixelSums& p = s.film.at(int(i % 5), int(i / 5));
    p = PixelSums{0.1 * double(i), 1.0 / 3, 1e-300, 2.5, uint32_t(i)};
  }
  return s;
}

TEST(JobStore, ACheckpointComesBackBitForBit) {
  const Saved s = sample();
  const Checkpoint c = decode_checkpoint(encode_checkpoint_v2(s.state, s.film, 12.5));
  EXPECT_EQ(c.elapsed, 12.5);
  EXPECT_EQ(c.film.window(), s.film.window());
  for (size_t i = 0; i < 20; ++i) {  // field by field: PixelSums has padding
    const PixelSums &a = c.film.pixels()[i], &b = s.film.pixels()[i];
    EXPECT_EQ(0, std::memcmp(&a, &b, offsetof(PixelSums, n))) << i;
    EXPECT_EQ(a.n, b.n) << i;
  }
  ASSERT_EQ(c.state.progress.size(), 2u);
  EXPECT_EQ(c.state.progress[1].passes_done, 3u);
  EXPECT_TRUE(c.state.progress[1].finished);
  EXPECT_EQ(c.state.progress[0].relative_error, 0.25f);
  EXPECT_EQ(c.state.active, s.state.active);
  EXPECT_EQ(c.state.samples_merged, 1234u);
  EXPECT_EQ(c.state.merges, 5u);
  EXPECT_EQ(c.state.work_done, 0.1);
  EXPECT_EQ(c.state.work_total, 3e9);
  // An ended job's progress without its film (start-up leaves finished films on disk).
  const Checkpoint progress_only = decode_checkpoint(encode_checkpoint_v2(s.state, s.film, 12.5), false);
  EXPECT_EQ(progress_only.film.window(), Rect{});
  EXPECT_EQ(progress_only.state.merges, 5u);
  EXPECT_EQ(progress_only.state.progress[1].passes_done, 3u);
}

TEST(JobStore, ALargeFilmComesBackBitForBitAcrossItsChunks) {
  // 300 x 300 pixels: the sums are written in pieces of 65,536 pixels, the last one short.
  Film film(Rect{0, 0, 300, 300});
  for (int y = 0; y < 300; ++y)
    for (int x = 0; x < 300; ++x)
      film.at(x, y) = PixelSums{x * 0.1, y / 3.0, x * 1e-3 + y, double(x * y), uint32_t(x + y)};
  PlanState state;
  state.progress = {{1, false, 0.5f}};
  const Checkpoint c = decode_checkpoint(encode_checkpoint_v2(state, film, 1));
  ASSERT_EQ(c.film.window(), film.window());
  for (size_t i = 0; i < film.pixels().size(); ++i) {
    const PixelSums &a = c.film.pixels()[i], &b = film.pixels()[i];
    ASSERT_EQ(0, std::memcmp(&a, &b, offsetof(PixelSums, n))) << i;
    ASSERT_EQ(a.n, b.n) << i;
  }
}

TEST(JobStore, ACheckpointOfTheFirstVersionIsStillRead) {
  // Version 1 kept the film's sums as one piece with no chunk size: what a coordinator
  // from before finds in its data folder after an upgrade.
  const Saved s = sample();
  std::string v2 = encode_checkpoint_v2(s.state, s.film, 7);
  const size_t film_bytes = encode_sums(s.film.pixels()).size();
  const size_t chunk_at = v2.size() - 8 - film_bytes - 8 - 4;
  std::string v1 = v2.substr(0, chunk_at) + v2.substr(chunk_at + 4, v2.size() - 8 - chunk_at - 4);
  const uint32_t version = 1;
  std::memcpy(v1.data() + 4, &version, 4);
  const Checkpoint c = decode_checkpoint(with_checksum(v1));
  EXPECT_EQ(c.elapsed, 7);
  ASSERT_EQ(c.film.window(), s.film.window());
  for (size_t i = 0; i < 20; ++i) EXPECT_EQ(c.film.pixels()[i].r, s.film.pixels()[i].r) << i;
  EXPECT_EQ(c.state.merges, 5u);
}

TEST(JobStore, EveryTruncatedOrDamagedCheckpointIsRefusedNeverTrusted) {
  const Saved s = sample();
  const std::string good = encode_checkpoint_v2(s.state, s.film, 1);
  for (size_t n = 0; n < good.size(); ++n) EXPECT_THROW(decode_checkpoint(good.substr(0, n)), std::runtime_error) << n;
  for (size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] ^= 0x01;
    EXPECT_THROW(decode_checkpoint(bad), std::runtime_error) << i;
  }
}

// ---- version 3: band by band ----

RenderSettings plan_settings(bool adaptive = false) {
  RenderSettings s;
  s.camera.width = 37;
  s.camera.height = 29;  // bands of 8 rows, the last one 5
  s.tile_size = 8;
  s.spp = 12;
  s.pass_spp = 4;
  s.adaptive = adaptive;
  s.adaptive_batch = 4;
  s.adaptive_tolerance = 0.3f;
  return s;
}

// A plan part of the way, its sums not round in binary.
FramePlan merged_plan(bool adaptive = false) {
  FramePlan plan(plan_settings(adaptive));
  for (int k = 0; k < 17; ++k) {
    const TileTask t = *plan.take();
    std::vector<PixelSums> sums(size_t(t.rect.area()));
    for (size_t i = 0; i < sums.size(); ++i) {
      if (!t.active.empty() && !t.active[i]) continue;
      const double v = 0.1 * double(i % 7) + 1.0 / 3;
      const uint32_t n = t.sample_end - t.sample_begin;
      sums[i] = PixelSums{v * n, v * n, v * n, v * v * n * (1 + 0.5 * double(i % 3)), n};
    }
    EXPECT_EQ(plan.merge(t.tile, t.pass, sums), FramePlan::Merge::kMerged);
  }
  return plan;
}

void expect_same_film(const Film& a, const Film& b) {
  ASSERT_EQ(a.window(), b.window());
  for (size_t i = 0; i < a.pixels().size(); ++i) {  // field by field: PixelSums has padding
    ASSERT_EQ(0, std::memcmp(&a.pixels()[i], &b.pixels()[i], offsetof(PixelSums, n))) << i;
    ASSERT_EQ(a.pixels()[i].n, b.pixels()[i].n) << i;
  }
}

TEST(JobStore, AVersion3CheckpointRestoresThePlanBitForBit) {
  for (const bool adaptive : {false, true}) {
    const FramePlan a = merged_plan(adaptive);
    const std::string bytes = encode_checkpoint(a, 12.5);
    FramePlan b(plan_settings(adaptive));
    EXPECT_EQ(read_checkpoint(bytes, b), 12.5);
    expect_same_film(a.film(), b.film());
    EXPECT_EQ(b.samples_merged(), a.samples_merged());
    EXPECT_EQ(b.tiles_done(), a.tiles_done());
    EXPECT_EQ(b.frame_passes_done(), a.frame_passes_done());
    for (uint32_t t = 0; t < a.tiles().size(); ++t) {
      EXPECT_EQ(b.progress(t).passes_done, a.progress(t).passes_done);
      EXPECT_EQ(b.progress(t).relative_error, a.progress(t).relative_error);
    }
    // An ended job's progress without its film.
    FramePlan c(plan_settings(adaptive));
    read_checkpoint(bytes, c, false);
    EXPECT_FALSE(c.has_film());
    EXPECT_EQ(c.samples_merged(), a.samples_merged());
    EXPECT_EQ(c.tiles_done(), a.tiles_done());
  }
}

TEST(JobStore, AVersion2CheckpointStillRestoresAPlan) {
  const FramePlan a = merged_plan(true);
  FramePlan b(plan_settings(true));
  EXPECT_EQ(read_checkpoint(encode_checkpoint_v2(a.state(), a.film(), 3), b), 3);
  expect_same_film(a.film(), b.film());
  EXPECT_EQ(b.merges(), a.merges());
}

// Found by audit: an old-format checkpoint's film window was allocated as the file declared
// (a crafted 104-byte file: 4096 x 4096 pixels, 650 MB, up to 160 GiB) before it was held
// against the job's, and the file read whole however long. Both are bounded by the job's film.
TEST(JobStore, AnOldCheckpointOfAnotherFrameIsRefusedBeforeItsFilmIsMade) {
  const FramePlan a = merged_plan(true);
  PlanState state = a.state();
  Film wide(Rect{0, 0, 512, 512});  // (a frame not the job's)
  state.active.clear();
  FramePlan b(plan_settings(true));
  try {
    read_checkpoint(encode_checkpoint_v2(state, wide, 3), b);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "checkpoint: it does not fit the job's frame");
  }
  std::string long_file = encode_checkpoint_v2(a.state(), a.film(), 3);
  long_file.insert(long_file.size() - 8, std::string(64 << 20, '\0'));
  try {
    read_checkpoint(long_file, b);
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("checkpoint: larger than the job's film could make"), std::string::npos)
        << e.what();
  }
}

// A finished frame's checkpoint without the film (SnapshotWriter writes it once the frame's
// image is on disk): its progress comes back as written; a film asked of it is refused,
// naming why, rather than a black one made up.
TEST(JobStore, ACheckpointWithoutTheFilmRestoresTheProgressAlone) {
  const FramePlan a = merged_plan(true);
  std::string bytes;
  {
    CheckpointEncoder enc(
        a, 3, [&](const std::string& b) { bytes += b; }, false);
    BandCopy band;
    for (uint32_t b = 0; b < a.bands(); ++b) {
      a.copy_band(b, &band);
      enc.band(band);
    }
    enc.finish();
  }
  EXPECT_LT(bytes.size() * 4, encode_checkpoint(a, 3).size());
  FramePlan b(plan_settings(true));
  EXPECT_EQ(read_checkpoint(bytes, b, false), 3);
  EXPECT_EQ(b.merges(), a.merges());
  EXPECT_EQ(b.samples_merged(), a.samples_merged());
  for (uint32_t t = 0; t < a.tiles().size(); ++t) EXPECT_EQ(b.progress(t).passes_done, a.progress(t).passes_done);
  FramePlan c(plan_settings(true));
  try {
    read_checkpoint(bytes, c, true);
    ADD_FAILURE() << "a film read from a checkpoint without one";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("it holds no film"), std::string::npos) << e.what();
  }
}

// Version 4 kept the splats' squared luminance in 2^-12 units (a splat under about 0.011
// added no variance); version 5 in 2^-32. A version 4 file, what a coordinator from before
// leaves in its data folder, is read in today's units (saturating, as the sums are).
TEST(JobStore, AVersion4CheckpointsSplatVarianceIsReadInTodaysUnits) {
  RenderSettings settings = plan_settings();
  settings.tile_size = 32;  // one band: one splat row block at the end of the file
  FramePlan a(settings);
  FrameSplats splats(settings, uint32_t(a.tiles().size()));
  SplatRecord r;
  r.paths = 10;
  r.entries.push_back({5, {1, 2, 3, 7}});
  r.entries.push_back({40, {4, 5, 6, 8}});
  splats.add(0, 0, {r});
  std::string v5 = encode_checkpoint(a, 2, &splats);
  // The last band's splat rows: u64 length, zstd bytes, then the u64 checksum.
  size_t at = v5.size() - 16;
  for (uint64_t len = 0; at > 0; --at) {
    std::memcpy(&len, v5.data() + at, 8);
    if (len == v5.size() - 8 - (at + 8)) break;
  }
  ASSERT_GT(at, 0u);
  const std::string z = v5.substr(at + 8, v5.size() - 8 - (at + 8));
  std::vector<SplatSums> rows(size_t(settings.camera.width) * settings.camera.height);
  ASSERT_EQ(ZSTD_decompress(rows.data(), rows.size() * sizeof(SplatSums), z.data(), z.size()),
            rows.size() * sizeof(SplatSums));
  ASSERT_EQ(rows[5].lum2, 7);
  rows[5].lum2 = 3;                  // 3 x 2^-12
  rows[40].lum2 = int64_t(1) << 50;  // past what 2^-32 units hold: saturates
  std::string z4(ZSTD_compressBound(rows.size() * sizeof(SplatSums)), '\0');
  z4.resize(ZSTD_compress(z4.data(), z4.size(), rows.data(), rows.size() * sizeof(SplatSums), 1));
  std::string v4 = v5.substr(0, at);
  const uint64_t len = z4.size();
  v4.append(reinterpret_cast<const char*>(&len), 8);
  v4 += z4;
  const uint32_t version = 4;
  std::memcpy(v4.data() + 4, &version, 4);
  v4.erase(33, 1);  // version 6's film flag (after magic, version, window, tiles, bands, adaptive)

  FramePlan b(settings);
  FrameSplats restored(settings, uint32_t(b.tiles().size()));
  EXPECT_EQ(read_checkpoint(with_checksum(v4), b, true, &restored), 2);
  ASSERT_TRUE(restored.any());
  const SplatFilm& film = *restored.film();
  EXPECT_EQ(film.paths(), 10u);
  EXPECT_EQ(film.at(5, 0).lum2, int64_t(3) << 20);
  EXPECT_EQ(film.at(5, 0).rgb[2], 3);
  EXPECT_EQ(film.at(3, 1).lum2, std::numeric_limits<int64_t>::max());
  // Today's file comes back as written.
  FramePlan c(settings);
  FrameSplats same(settings, uint32_t(c.tiles().size()));
  read_checkpoint(v5, c, true, &same);
  EXPECT_EQ(same.film()->at(5, 0).lum2, 7);
  EXPECT_EQ(same.film()->at(3, 1).lum2, 8);
}

TEST(JobStore, EveryTruncatedOrDamagedVersion3CheckpointIsRefused) {
  const std::string good = encode_checkpoint(merged_plan(true), 1);
  for (size_t n = 0; n < good.size(); n += std::max<size_t>(1, n / 50)) {
    FramePlan p(plan_settings(true));
    EXPECT_THROW(read_checkpoint(good.substr(0, n), p), std::runtime_error) << n;
  }
  for (size_t i = 0; i < good.size(); i += 1 + i / 40) {
    std::string bad = good;
    bad[i] ^= 0x01;
    FramePlan p(plan_settings(true));
    EXPECT_THROW(read_checkpoint(bad, p), std::runtime_error) << i;
  }
  FramePlan other(plan_settings(false));  // another job's frame
  EXPECT_THROW(read_checkpoint(good, other), std::runtime_error);
  FramePlan p(plan_settings(true));
  EXPECT_THROW(read_checkpoint(good + "x", p), std::runtime_error);  // trailing bytes
}

TEST(JobStore, JobsAndGenerationsSurviveReopening) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_store_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  {
    SqliteJobStore store(dir.string());
    EXPECT_EQ(store.next_generation(), 1u);
    StoredJob j;
    j.meta.id = "00000000000000ab";
    j.meta.name = "it's \"quoted\"; DROP TABLE jobs; --";
    j.meta.owner = "ann";
    j.meta.scene_hash = "h";
    j.meta.main_file = "scene.dae";
    j.meta.priority = -3;
    j.meta.seq = 7;
    j.meta.settings.set_spp(99);
    j.meta.submitted_at = 1764179999.25;  // wall clock: shown to users after a restart too
    store.add(j);
    StoredJob k = j;
    k.meta.id = "00000000000000cd";
    k.meta.seq = 8;
    store.add(k);
    EXPECT_THROW(store.add(k), std::runtime_error);  // one row per id
    store.end(j.meta.id, v1::JobStatus::CANCELLED, "by ann", 4.5);
    write_checkpoint(store, k.meta.id, merged_plan(), 2);
  }
  SqliteJobStore store(dir.string());
  EXPECT_EQ(store.next_generation(), 2u);
  const std::vector<StoredJob> jobs = store.jobs();
  ASSERT_EQ(jobs.size(), 2u);
  EXPECT_EQ(jobs[0].meta.name, "it's \"quoted\"; DROP TABLE jobs; --");
  EXPECT_EQ(jobs[0].state, v1::JobStatus::CANCELLED);
  EXPECT_EQ(jobs[0].error, "by ann");
  EXPECT_EQ(jobs[0].elapsed, 4.5);
  EXPECT_EQ(jobs[0].meta.priority, -3);
  EXPECT_EQ(jobs[0].meta.settings.spp(), 99u);
  EXPECT_EQ(jobs[0].meta.submitted_at, 1764179999.25);
  EXPECT_EQ(jobs[1].state, v1::JobStatus::QUEUED);
  FramePlan plan(plan_settings());
  EXPECT_FALSE(store.read_checkpoint(jobs[0].meta.id, plan));
  const std::optional<double> elapsed = store.read_checkpoint(jobs[1].meta.id, plan);
  ASSERT_TRUE(elapsed);
  EXPECT_EQ(*elapsed, 2);
  expect_same_film(plan.film(), merged_plan().film());
  EXPECT_FALSE(fs::exists(store.checkpoint_path(jobs[1].meta.id) + ".tmp"));
  fs::remove_all(dir);
}

// Issue 22: what delete, requeue, priority and retention write survives reopening; an end
// keeps its first time when written again; a database from before ended_at gives its ended
// jobs a full retention period from the upgrade.
StoredJob row(const std::string& id, uint64_t seq) {
  StoredJob j;
  j.meta.id = id;
  j.meta.seq = seq;
  j.meta.scene_hash = "shared";
  j.meta.settings.set_spp(4);
  return j;
}

TEST(JobStore, RequeueDeletePriorityAndEndTimesSurviveReopening) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_store_life_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  double wall = 1000;
  {
    SqliteJobStore store(dir.string());
    store.wall = [&wall] { return wall; };
    store.add(row("a", 1));
    store.add(row("b", 2));
    store.add(row("c", 3));
    store.end("a", v1::JobStatus::DONE, "", 1);
    wall = 1010;
    store.end("b", v1::JobStatus::CANCELLED, "", 1);
    store.end("a", v1::JobStatus::DONE, "a liar's tiles", 1);  // written again: keeps 1000
    store.set_priority("c", 9);
    EXPECT_EQ(store.scene_users("shared"), 3u);
    write_checkpoint(store, "b", merged_plan(), 2);
  }
  SqliteJobStore store(dir.string());
  store.wall = [&wall] { return wall; };
  wall = 1020;
  EXPECT_EQ(store.ended_before(15, 10), std::vector<std::string>{"a"});
  EXPECT_EQ(store.ended_before(5, 10), (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(store.ended_before(5, 1), std::vector<std::string>{"a"});
  store.requeue("b");
  EXPECT_EQ(store.ended_before(0, 10), std::vector<std::string>{"a"});
  store.remove("a", {"a"});
  store.remove("b", {"b"});
  EXPECT_FALSE(fs::exists(store.checkpoint_path("b")));
  const std::vector<StoredJob> jobs = store.jobs();
  ASSERT_EQ(jobs.size(), 1u);
  EXPECT_EQ(jobs[0].meta.id, "c");
  EXPECT_EQ(jobs[0].meta.priority, 9);
  EXPECT_EQ(store.scene_users("shared"), 1u);
  fs::remove_all(dir);

  // A database without the ended_at column (before this change): added, its ended rows
  // stamped with the time of the upgrade.
  {
    SqliteJobStore old(dir.string());
    old.add(row("x", 1));
    old.end("x", v1::JobStatus::DONE, "", 1);
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir / "coordinator.db").string().c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "ALTER TABLE jobs DROP COLUMN ended_at", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  SqliteJobStore upgraded(dir.string());  // its wall clock: now
  EXPECT_TRUE(upgraded.ended_before(3600, 10).empty());
  EXPECT_EQ(upgraded.ended_before(-3600, 10), std::vector<std::string>{"x"});
  fs::remove_all(dir);
}

// Issue 23: deleting coordinator.db, or only its write-ahead log after an unclean stop,
// started an empty farm without a word (and, with no job using them, deleted the folder's
// live scene bundles). The data folder's marker makes both a refusal that says what to do.
TEST(JobStore, ALostDatabaseIsRefusedNotReplacedByAnEmptyOne) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_store_lost_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  { SqliteJobStore(dir.string()).add(row("a", 1)); }  // a clean close
  EXPECT_FALSE(fs::exists(dir / "coordinator.db-wal"));
  { EXPECT_EQ(SqliteJobStore(dir.string()).jobs().size(), 1u); }  // reopens without complaint
  fs::remove(dir / "coordinator.db");
  try {
    SqliteJobStore store(dir.string());
    ADD_FAILURE() << "an empty database was made over a lost one";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("coordinator.db is missing, but this data folder held"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
  // Left open (a crash), then its write-ahead log deleted: the latest commits are gone.
  {
    SqliteJobStore running(dir.string());
    running.add(row("b", 1));
    ASSERT_TRUE(fs::exists(dir / "coordinator.db-wal"));
    std::error_code ec;
    fs::copy_file(dir / "coordinator.db", dir / "crashed.db", ec);
    fs::copy_file(dir / "DATA-FOLDER", dir / "crashed.marker", ec);
  }
  fs::rename(dir / "crashed.db", dir / "coordinator.db");  // as a kill -9 leaves it, without its WAL
  fs::rename(dir / "crashed.marker", dir / "DATA-FOLDER");
  try {
    SqliteJobStore store(dir.string());
    ADD_FAILURE() << "opened without its write-ahead log";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("coordinator.db-wal is missing"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
  // A folder from before markers (none): opened, and marked from then on.
  { SqliteJobStore(dir.string()).add(row("c", 1)); }
  fs::remove(dir / "DATA-FOLDER");
  { EXPECT_EQ(SqliteJobStore(dir.string()).jobs().size(), 1u); }
  EXPECT_TRUE(fs::exists(dir / "DATA-FOLDER"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera

namespace tessera {
namespace {

// Found by audit: two coordinators on one data folder each took up every job. The folder is
// locked while a store has it open, and let go when it closes.
TEST(JobStore, OneStoreADataFolder) {
  const fs::path dir = fs::temp_directory_path() / ("tessera_store_lock_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  {
    SqliteJobStore first(dir.string());
    try {
      SqliteJobStore second(dir.string());
      ADD_FAILURE();
    } catch (const std::runtime_error& e) {
      EXPECT_NE(
          std::string(e.what()).find("data folder " + dir.string() + " is in use by another coordinator (process " +
                                     std::to_string(::getpid()) + ")"),
          std::string::npos)
          << e.what();
    }
  }
  EXPECT_NO_THROW(SqliteJobStore{dir.string()});  // let go with the first
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
