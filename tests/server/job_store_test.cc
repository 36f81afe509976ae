// The job database and film checkpoints: what a restarted coordinator reads back.
#include "server/job_store.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstddef>
#include <cstring>
#include <filesystem>
#define XXH_INLINE_ALL
#include <xxhash.h>

#include "proto/wire.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

struct Saved {
  PlanState state;
  Film film{Rect{2, 3, 5, 4}};
};

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
    PixelSums &p = s.film.at(int(i % 5), int(i / 5));
    p = PixelSums{0.1 * double(i), 1.0 / 3, 1e-300, 2.5, uint32_t(i)};
  }
  return s;
}

TEST(JobStore, ACheckpointComesBackBitForBit) {
  const Saved s = sample();
  const Checkpoint c = decode_checkpoint(encode_checkpoint(s.state, s.film, 12.5));
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
  const Checkpoint progress_only = decode_checkpoint(encode_checkpoint(s.state, s.film, 12.5), false);
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
  const Checkpoint c = decode_checkpoint(encode_checkpoint(state, film, 1));
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
  std::string v2 = encode_checkpoint(s.state, s.film, 7);
  const size_t film_bytes = encode_sums(s.film.pixels()).size();
  const size_t chunk_at = v2.size() - 8 - film_bytes - 8 - 4;
  std::string v1 = v2.substr(0, chunk_at) + v2.substr(chunk_at + 4, v2.size() - 8 - chunk_at - 4);
  const uint32_t version = 1;
  std::memcpy(v1.data() + 4, &version, 4);
  const uint64_t sum = XXH64(v1.data(), v1.size(), 0);
  v1.append(reinterpret_cast<const char *>(&sum), 8);
  const Checkpoint c = decode_checkpoint(v1);
  EXPECT_EQ(c.elapsed, 7);
  ASSERT_EQ(c.film.window(), s.film.window());
  for (size_t i = 0; i < 20; ++i) EXPECT_EQ(c.film.pixels()[i].r, s.film.pixels()[i].r) << i;
  EXPECT_EQ(c.state.merges, 5u);
}

TEST(JobStore, EveryTruncatedOrDamagedCheckpointIsRefusedNeverTrusted) {
  const Saved s = sample();
  const std::string good = encode_checkpoint(s.state, s.film, 1);
  for (size_t n = 0; n < good.size(); ++n) EXPECT_THROW(decode_checkpoint(good.substr(0, n)), std::runtime_error) << n;
  for (size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] ^= 0x01;
    EXPECT_THROW(decode_checkpoint(bad), std::runtime_error) << i;
  }
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
    store.add(j);
    StoredJob k = j;
    k.meta.id = "00000000000000cd";
    k.meta.seq = 8;
    store.add(k);
    EXPECT_THROW(store.add(k), std::runtime_error);  // one row per id
    store.end(j.meta.id, v1::JobStatus::CANCELLED, "by ann", 4.5);
    const Saved s = sample();
    store.write_checkpoint(k.meta.id, s.state, s.film, 2);
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
  EXPECT_EQ(jobs[1].state, v1::JobStatus::QUEUED);
  EXPECT_FALSE(store.read_checkpoint(jobs[0].meta.id));
  const std::optional<Checkpoint> c = store.read_checkpoint(jobs[1].meta.id);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->state.merges, 5u);
  EXPECT_FALSE(fs::exists(store.checkpoint_path(jobs[1].meta.id) + ".tmp"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace tessera
