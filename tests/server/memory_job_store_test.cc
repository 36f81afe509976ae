// MemoryJobStore, the unit tests' JobStore, against SqliteJobStore, the real one: the same
// tests over both, so that what a test learns from the fake holds for the coordinator.
// (job_store_test.cc tests the SQLite store and the checkpoint format themselves.)
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <type_traits>
#include <utility>

#include "server/checkpoint.h"
#include "server/job_store.h"
#include "tests/server/parts_fixture.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;

template <typename Store>
class JobStoreContract : public ::testing::Test {
 protected:
  const fs::path dir = fs::temp_directory_path() / ("tessera_stores_" + std::to_string(::getpid()));
  std::unique_ptr<Store> store = open();

  std::unique_ptr<Store> open() const {
    if constexpr (std::is_same_v<Store, SqliteJobStore>)
      return std::make_unique<SqliteJobStore>(dir.string());
    else
      return std::make_unique<Store>();
  }
  void TearDown() override {
    store.reset();
    fs::remove_all(dir);
  }
  // The job's checkpoint replaced by these bytes, as a crash or a bad disk may leave it.
  void replace_checkpoint(const std::string& id, const std::string& bytes) {
    if constexpr (std::is_same_v<Store, SqliteJobStore>) {
      const fs::path path = store->checkpoint_path(id);
      fs::create_directories(path.parent_path());
      std::ofstream(path, std::ios::binary) << bytes;
    } else {
      store->set_checkpoint_bytes(id, bytes);
    }
  }
  static StoredJob row(const std::string& id, uint64_t seq) {
    StoredJob j;
    j.meta.id = id;
    j.meta.name = "it's \"quoted\"";
    j.meta.owner = "ann";
    j.meta.scene_hash = "0123abcd";
    j.meta.main_file = "scenes/a.dae";
    j.meta.priority = -3;
    j.meta.seq = seq;
    j.meta.settings = to_proto(testing::small_settings());
    j.frames = {4, -2, 7};
    return j;
  }
};

using Stores = ::testing::Types<MemoryJobStore, SqliteJobStore>;
TYPED_TEST_SUITE(JobStoreContract, Stores);

TYPED_TEST(JobStoreContract, GenerationsCountFromOne) {
  EXPECT_EQ(this->store->next_generation(), 1u);
  EXPECT_EQ(this->store->next_generation(), 2u);
}

// Archive (archive.h): an ended row takes a job's last status and leaves the start's rows;
// a live one does not; pages, counts and a liar's flags read and change them.
TYPED_TEST(JobStoreContract, AnArchivedRowKeepsItsSummaryAndLeavesTheRowsAStartTakesUp) {
  auto& store = *this->store;
  StoredJob a = this->row("000000000000000a", 1), b = this->row("000000000000000b", 2);
  b.frames.clear();
  store.add(a);
  store.add(b);
  EXPECT_FALSE(store.archive(a.meta.id, "summary of a", {{7, 3}}));  // live: not taken
  store.end(a.meta.id, v1::JobStatus::DONE, "", 1.5);
  store.end(b.meta.id, v1::JobStatus::CANCELLED, "stopped", 0.5);
  EXPECT_TRUE(store.archive(a.meta.id, "summary of a", {{7, 3}, {8, 1}}));
  EXPECT_TRUE(store.archive(b.meta.id, "summary of b", {{7, 2}}));
  EXPECT_TRUE(store.jobs().empty());  // nothing for a start to take up
  EXPECT_EQ(store.job(a.meta.id)->summary, "summary of a");
  EXPECT_FALSE(store.job("nope"));
  EXPECT_EQ(store.count(), 2u);
  const std::vector<StoredJob> page = store.page(1, 10);
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].meta.id, b.meta.id);
  EXPECT_EQ(page[0].summary, "summary of b");
  EXPECT_EQ(store.page(0, 1).at(0).meta.id, a.meta.id);
  ASSERT_EQ(store.newest(1).size(), 1u);
  EXPECT_EQ(store.newest(1)[0].meta.id, b.meta.id);
  EXPECT_EQ(store.newest(5).size(), 2u);
  EXPECT_EQ(store.newest(5)[0].meta.id, a.meta.id);  // in submission order
  EXPECT_EQ(store.archived_names().size(), 2u);
  const std::array<uint64_t, 5> states = store.archived_states();
  EXPECT_EQ(states[v1::JobStatus::DONE], 1u);
  EXPECT_EQ(states[v1::JobStatus::CANCELLED], 1u);
  // Worker 7 was lying: both are flagged but b, flagged in memory; its records go.
  std::vector<std::pair<uint32_t, bool>> asked;
  store.flag_merged(7, {b.meta.id}, [&](uint32_t tiles, bool sequence) {
    asked.emplace_back(tiles, sequence);
    return "liar";
  });
  ASSERT_EQ(asked.size(), 1u);
  EXPECT_EQ(asked[0], std::make_pair(3u, true));  // a is a sequence
  EXPECT_EQ(store.job(a.meta.id)->error, "liar");
  EXPECT_EQ(store.job(b.meta.id)->error, "stopped");
  store.flag_merged(7, {}, [](uint32_t, bool) { return "again"; });  // its records are gone
  EXPECT_EQ(store.job(a.meta.id)->error, "liar");
  store.flag_merged(8, {}, [](uint32_t, bool) { return "second"; });
  EXPECT_EQ(store.job(a.meta.id)->error, "liar; second");
  // A requeued row is in memory again: no summary, taken up at a start.
  store.requeue(b.meta.id);
  EXPECT_TRUE(store.job(b.meta.id)->summary.empty());
  ASSERT_EQ(store.jobs().size(), 1u);
  EXPECT_EQ(store.archived_names().size(), 1u);
  store.forget_merges();
  store.remove(a.meta.id, {});
  EXPECT_EQ(store.count(), 1u);
}

TYPED_TEST(JobStoreContract, ARowComesBackFieldForField) {
  const StoredJob in = this->row("00000000000000ab", 5);
  this->store->add(in);
  const std::vector<StoredJob> rows = this->store->jobs();
  ASSERT_EQ(rows.size(), 1u);
  const StoredJob& out = rows[0];
  EXPECT_EQ(out.meta.id, in.meta.id);
  EXPECT_EQ(out.meta.name, in.meta.name);
  EXPECT_EQ(out.meta.owner, in.meta.owner);
  EXPECT_EQ(out.meta.scene_hash, in.meta.scene_hash);
  EXPECT_EQ(out.meta.main_file, in.meta.main_file);
  EXPECT_EQ(out.meta.priority, in.meta.priority);
  EXPECT_EQ(out.meta.seq, in.meta.seq);
  EXPECT_EQ(out.meta.settings.SerializeAsString(), in.meta.settings.SerializeAsString());
  EXPECT_EQ(out.state, v1::JobStatus::QUEUED);
  EXPECT_EQ(out.error, "");
  EXPECT_EQ(out.elapsed, 0);
  EXPECT_EQ(out.frames, in.frames);
  this->store->ping();  // it answers
}

TYPED_TEST(JobStoreContract, AnEndRewritesThatRowsStateErrorAndElapsedOnly) {
  this->store->add(this->row("00000000000000ab", 1));
  this->store->add(this->row("00000000000000cd", 2));
  this->store->end("00000000000000ab", v1::JobStatus::FAILED, "tasks failed", 12.5);
  this->store->end("ffffffffffffffff", v1::JobStatus::DONE, "", 1);  // no such row: nothing
  const std::vector<StoredJob> rows = this->store->jobs();
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].state, v1::JobStatus::FAILED);
  EXPECT_EQ(rows[0].error, "tasks failed");
  EXPECT_EQ(rows[0].elapsed, 12.5);
  EXPECT_EQ(rows[0].meta.owner, "ann");
  EXPECT_EQ(rows[1].state, v1::JobStatus::QUEUED);
  EXPECT_EQ(rows[1].elapsed, 0);
}

TYPED_TEST(JobStoreContract, ACheckpointComesBackWithOrWithoutItsFilm) {
  FramePlan read(testing::small_settings());
  EXPECT_FALSE(this->store->read_checkpoint("00000000000000ab", read));
  FramePlan plan(testing::small_settings());
  testing::merge_passes(plan, 1);
  write_checkpoint(*this->store, "00000000000000ab", plan, 2.5);
  std::optional<double> elapsed = this->store->read_checkpoint("00000000000000ab", read);
  ASSERT_TRUE(elapsed);
  EXPECT_EQ(*elapsed, 2.5);
  EXPECT_EQ(read.merges(), plan.merges());
  ASSERT_EQ(read.film().window(), plan.film().window());
  for (size_t i = 0; i < plan.film().pixels().size(); ++i)
    ASSERT_EQ(read.film().pixels()[i].lum2, plan.film().pixels()[i].lum2) << i;
  FramePlan progress(testing::small_settings());
  ASSERT_TRUE(this->store->read_checkpoint("00000000000000ab", progress, false));
  EXPECT_FALSE(progress.has_film());
  EXPECT_EQ(progress.samples_merged(), plan.samples_merged());
  testing::merge_passes(plan, 2);  // a later checkpoint replaces it
  write_checkpoint(*this->store, "00000000000000ab", plan, 4);
  FramePlan later(testing::small_settings());
  this->store->read_checkpoint("00000000000000ab", later);
  EXPECT_EQ(later.merges(), plan.merges());
  EXPECT_FALSE(this->store->read_checkpoint("00000000000000cd", later));  // each job its own
}

TYPED_TEST(JobStoreContract, ADamagedCheckpointIsRefusedNotTrusted) {
  FramePlan plan(testing::small_settings());
  testing::merge_passes(plan, 1);
  std::string bytes = encode_checkpoint(plan, 1);
  bytes[bytes.size() / 3] ^= 0x04;
  this->replace_checkpoint("00000000000000ab", bytes);
  FramePlan a(testing::small_settings()), b(testing::small_settings());
  EXPECT_THROW(this->store->read_checkpoint("00000000000000ab", a), std::runtime_error);
  EXPECT_THROW(this->store->read_checkpoint("00000000000000ab", b, false), std::runtime_error);
}

// Where the fake once differed from SQLite (found writing these tests):

// SQLite returns rows ORDER BY seq; MemoryJobStore in the order they were added. Two
// submits racing each other record their rows outside the lock, so the order added can
// differ from the order of submission.
TYPED_TEST(JobStoreContract, RowsComeBackInSubmissionOrderWhateverTheOrderAdded) {
  this->store->add(this->row("00000000000000cd", 2));
  this->store->add(this->row("00000000000000ab", 1));
  const std::vector<StoredJob> rows = this->store->jobs();
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].meta.seq, 1u);
  EXPECT_EQ(rows[1].meta.seq, 2u);
}

// SQLite refuses a second row with the same id (its primary key); MemoryJobStore keeps both.
TYPED_TEST(JobStoreContract, AnIdIsRecordedOnce) {
  this->store->add(this->row("00000000000000ab", 1));
  EXPECT_THROW(this->store->add(this->row("00000000000000ab", 2)), std::runtime_error);
  EXPECT_EQ(this->store->jobs().size(), 1u);
}

// A row's scene_bytes is not stored (a restart counts the bundle again): SQLite gives 0,
// MemoryJobStore what was added.
TYPED_TEST(JobStoreContract, SceneBytesAreNotStored) {
  StoredJob in = this->row("00000000000000ab", 1);
  in.meta.scene_bytes = 99;
  this->store->add(in);
  EXPECT_EQ(this->store->jobs().at(0).meta.scene_bytes, 0u);
}

}  // namespace
}  // namespace tessera
