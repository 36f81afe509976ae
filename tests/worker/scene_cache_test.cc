// The worker's scene cache (worker/scene_cache.h) over a fake coordinator
// (fake_coordinator.h): scenes fetched once per content hash, in pieces, resumed, shared by
// workers on one folder, refused when their bytes are not the scene's; renderers kept
// within their count and memory bounds, scenes within the disk bound.
#include "worker/scene_cache.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <thread>

#include "core/io/files.h"
#include "tests/core/test_paths.h"
#include "tests/worker/fake_coordinator.h"
#include "wire.h"

namespace tessera {
namespace {

namespace fs = std::filesystem;
using testing::bundle_of;
using testing::FakeCoordinator;

const std::string kScene = testing::source_path("scenes/cornell-spheres.dae");

// The fetcher's call (worker/fetcher.cc), made to a fake coordinator.
worker::SceneCache::FetchChunks fetch_from(FakeCoordinator& fake) {
  return [&fake](const v1::FetchSceneRequest& req, const std::function<void(const v1::SceneChunk&)>& piece) {
    grpc::ClientContext ctx;
    const auto reader = fake.FetchSceneChunks(&ctx, req);
    v1::SceneChunk chunk;
    while (reader->Read(&chunk)) piece(chunk);
    return reader->Finish();
  };
}

v1::Task scene_task(const std::string& hash) {
  RenderSettings s;
  s.camera.width = 8;
  s.camera.height = 8;
  v1::Task t;
  t.set_scene_hash(hash);
  *t.mutable_settings() = to_proto(s);
  return t;
}

// What a folder holds: relative path -> bytes.
std::map<std::string, std::string> files_in(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) out[fs::relative(e.path(), dir).string()] = read_file_bytes(e.path().string());
  return out;
}

// The scene cache over a fake coordinator: the cornell scene, fetched in pieces of 1000 bytes.
class SceneCacheTest : public ::testing::Test {
 protected:
  const fs::path dir = fs::temp_directory_path() / ("tessera_scene_cache_" + std::to_string(::getpid()) + "_" +
                                                    ::testing::UnitTest::GetInstance()->current_test_info()->name());
  FakeCoordinator fake;
  std::string hash;

  void SetUp() override {
    const v1::SceneBundle bundle = bundle_of(kScene, &hash);
    fake.scenes[hash] = bundle;
  }
  void TearDown() override { fs::remove_all(dir); }
  // What prepare() throws, as E, for a task of this scene.
  template <typename E>
  std::string refusal() {
    try {
      worker::SceneCache(dir.string(), fetch_from(fake)).prepare(scene_task(hash));
    } catch (const E& e) {
      return e.what();
    }
    ADD_FAILURE() << "not refused";
    return "";
  }
};

// Scenes are fetched once per content hash and kept on disk for the next worker.
TEST_F(SceneCacheTest, FetchesASceneOnceAndKeepsItOnDisk) {
  v1::Task t = scene_task(hash);
  {
    worker::SceneCache cache(dir.string(), fetch_from(fake));
    const auto a = cache.prepare(t);
    RenderSettings s = from_proto(t.settings());
    s.max_depth = 3;
    *t.mutable_settings() = to_proto(s);
    const auto b = cache.prepare(t);  // other settings: another renderer of the same scene
    EXPECT_NE(a, b);
    EXPECT_EQ(a->scene, b->scene);
    EXPECT_EQ(cache.prepare(t), b);
  }
  worker::SceneCache again(dir.string(), fetch_from(fake));
  EXPECT_NE(again.prepare(t), nullptr);
  EXPECT_EQ(fake.scene_fetches, 1);
  t.set_scene_hash("../../etc");
  EXPECT_THROW(again.prepare(t), WireError);
}

// A worker held every scene it had ever loaded, for good (a farm running for months grew
// its workers' memory scene by scene). A scene now goes with the last renderer that uses
// it, the cache keeping the latest kKeptRenderers, and comes back from the disk cache.
TEST_F(SceneCacheTest, AScenesMemoryGoesWithItsLastRenderer) {
  std::string other;
  const v1::SceneBundle second = bundle_of(testing::source_path("scenes/cornell-spheres.gltf"), &other);
  fake.scenes[other] = second;
  auto task = [](const std::string& h, int max_depth) {
    v1::Task t = scene_task(h);
    RenderSettings s = from_proto(t.settings());
    s.max_depth = max_depth;
    *t.mutable_settings() = to_proto(s);
    return t;
  };
  worker::SceneCache cache(dir.string(), fetch_from(fake));
  const std::weak_ptr<const Scene> first = cache.prepare(task(hash, 5))->scene;
  EXPECT_EQ(cache.scenes_held(), 1u);
  for (int d = 0; d < int(worker::SceneCache::kKeptRenderers); ++d) cache.prepare(task(other, d + 1));
  EXPECT_TRUE(first.expired());  // its only renderer left the cache
  EXPECT_EQ(cache.scenes_held(), 1u);
  EXPECT_NE(cache.prepare(task(hash, 5)), nullptr);  // loaded again from the disk cache
  EXPECT_EQ(cache.scenes_held(), 2u);
  EXPECT_EQ(fake.scene_fetches, 2);  // each scene fetched once
}

// Kept renderers (and their scenes, BVHs, environment maps) are dropped oldest first while
// the worker's resident memory is above its bound; the newest is always kept.
TEST_F(SceneCacheTest, KeptRenderersGoOldestFirstAboveTheMemoryBound) {
  auto task = [&](int max_depth) {
    v1::Task t = scene_task(hash);
    RenderSettings s = from_proto(t.settings());
    s.max_depth = max_depth;
    *t.mutable_settings() = to_proto(s);
    return t;
  };
  worker::SceneCache cache(dir.string(), fetch_from(fake), {0, 3600, 1});  // 1 byte: always above
  cache.prepare(task(1));
  {
    const auto b = cache.prepare(task(2));
    EXPECT_EQ(cache.renderers_kept(), 1u);  // the newest alone
    EXPECT_EQ(cache.prepare(task(2)), b);   // (and kept: the same job's next task builds nothing)
  }
  // A renderer a task holds stays: dropping it would free nothing.
  const auto held = cache.prepare(task(3));
  cache.prepare(task(4));
  EXPECT_EQ(cache.renderers_kept(), 2u);
  EXPECT_EQ(cache.prepare(task(3)), held);
  worker::SceneCache roomy(dir.string(), fetch_from(fake), {0, 3600, uint64_t(1) << 50});
  roomy.prepare(task(1));
  roomy.prepare(task(2));
  EXPECT_EQ(roomy.renderers_kept(), 2u);
}

// A worker's disk cache kept every scene it had ever fetched. After a fetch, the scenes
// least recently used go until the folder is within its bound; never the one just fetched,
// nor one used within min_idle_seconds (another worker sharing the folder may be loading it).
TEST_F(SceneCacheTest, TheDiskCacheKeepsWithinItsBoundLeastRecentlyUsedFirst) {
  std::string other;
  const v1::SceneBundle second = bundle_of(testing::source_path("scenes/cornell-spheres.gltf"), &other);
  fake.scenes[other] = second;
  auto folder_bytes = [&](const std::string& h) {
    uint64_t n = 0;
    for (const auto& e : fs::recursive_directory_iterator(dir / h))
      if (e.is_regular_file()) n += e.file_size();
    return n;
  };
  {  // no bound on idle time: each fetch leaves room for itself alone
    worker::SceneCache cache(dir.string(), fetch_from(fake), {1, 0});
    cache.prepare(scene_task(hash));
    EXPECT_TRUE(fs::exists(dir / hash));  // the scene just fetched stays, whatever its size
    cache.prepare(scene_task(other));
    EXPECT_TRUE(fs::exists(dir / hash));  // in this worker's memory: its files may still be read
  }
  {  // a worker that holds only the second: the first, least recently used, goes
    worker::SceneCache cache(dir.string(), fetch_from(fake), {1, 0});
    fs::remove_all(dir / other);
    cache.prepare(scene_task(other));
    EXPECT_FALSE(fs::exists(dir / hash));
    EXPECT_TRUE(fs::exists(dir / other));
  }
  EXPECT_EQ(fake.scene_fetches, 3);
  {  // room for both: nothing goes
    worker::SceneCache cache(dir.string(), fetch_from(fake), {folder_bytes(other) * 3, 0});
    cache.prepare(scene_task(hash));
    EXPECT_TRUE(fs::exists(dir / hash));
    EXPECT_TRUE(fs::exists(dir / other));
  }
  EXPECT_EQ(fake.scene_fetches, 4);  // the first fetched again
  {                                  // used within the idle time: kept over the bound
    worker::SceneCache cache(dir.string(), fetch_from(fake), {1, 3600});
    fs::remove_all(dir / other);
    cache.prepare(scene_task(other));
    EXPECT_TRUE(fs::exists(dir / hash));
  }
}

// Workers sharing a cache folder: one's disk bound removed a scene another had in memory
// (unused for over min_idle_seconds: a long task), whose renderers of other settings may
// read its files again, or was loading (between reading its marker and marking it used).
// A worker now holds a lock on each scene it loads or holds; the bound skips those, and
// takes them once let go.
TEST_F(SceneCacheTest, TheDiskBoundLeavesAloneScenesAnotherWorkerHolds) {
  std::string other;
  fake.scenes[other] = bundle_of(testing::source_path("scenes/cornell-spheres.gltf"), &other);
  FakeCoordinator second;
  second.scenes = fake.scenes;
  auto holder = std::make_unique<worker::SceneCache>(dir.string(), fetch_from(fake));
  auto held = holder->prepare(scene_task(hash));
  const auto long_ago = fs::file_time_type::clock::now() - std::chrono::hours(2);
  fs::last_write_time(dir / hash / ".main", long_ago);
  {
    worker::SceneCache trimmer(dir.string(), fetch_from(second), {1, 0});
    trimmer.prepare(scene_task(other));
    EXPECT_TRUE(fs::exists(dir / hash / ".main"));
    EXPECT_EQ(files_in(dir / hash).size(), 2u);  // the scene and its marker, whole
  }
  EXPECT_NE(holder->prepare(scene_task(hash)), nullptr);  // (from memory)
  held.reset();
  holder.reset();  // its renderers and the scene with them: the lock goes
  fs::last_write_time(dir / hash / ".main", long_ago);
  fs::remove_all(dir / other);
  worker::SceneCache trimmer(dir.string(), fetch_from(second), {1, 0});
  trimmer.prepare(scene_task(other));
  EXPECT_FALSE(fs::exists(dir / hash));
  for (const fs::directory_entry& e : fs::directory_iterator(dir))  // (removed by way of a folder aside)
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
  EXPECT_EQ(fake.scene_fetches + second.scene_fetches, 3);
}

// A bundle of three files, 7475 + 5000 + 0 bytes. The connection is lost twice, after 3
// pieces each time: each fetch goes on from the first byte it lacks, and the files on disk
// are the bundle's, byte for byte.
TEST_F(SceneCacheTest, AFetchCutShortGoesOnFromTheFirstByteItLacks) {
  v1::SceneBundle b = fake.scenes[hash];
  v1::SceneFile* tex = b.add_files();
  tex->set_path("textures/noise.bin");
  for (int i = 0; i < 5000; ++i) tex->mutable_content()->push_back(char(i * 7));
  b.add_files()->set_path("empty.txt");
  hash = bundle_hash(b.main_file(), b.files());
  fake.scenes[hash] = b;
  fake.scene_streams_to_cut = 2;
  fake.cut_after_pieces = 3;
  worker::SceneCache cache(dir.string(), fetch_from(fake));
  ASSERT_NE(cache.prepare(scene_task(hash)), nullptr);
  ASSERT_EQ(fake.scene_requests.size(), 3u);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(fake.scene_requests[size_t(i)].file(), 0u);
    EXPECT_EQ(fake.scene_requests[size_t(i)].offset(), 3000u * uint64_t(i));
  }
  std::map<std::string, std::string> want{{".main", b.main_file() + "\n"}};
  for (const v1::SceneFile& f : b.files()) want[f.path()] = f.content();
  EXPECT_EQ(files_in(dir / hash), want);
  for (const fs::directory_entry& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
}

// Workers that share a cache folder (two on one machine) fetch the same scene at once:
// each into a partial folder of its own, the first in place is used by both (they hashed
// the same). A dead worker's partial folder is removed; a live one's is left alone.
TEST_F(SceneCacheTest, WorkersSharingACacheFolderFetchTheSameSceneAtOnce) {
  fs::create_directories(dir / (hash + ".partial-999999999-0"));  // no such process
  const fs::path live = dir / (hash + ".partial-" + std::to_string(::getppid()) + "-0");
  fs::create_directories(live);
  FakeCoordinator other;
  other.scenes = fake.scenes;
  std::shared_ptr<const worker::PreparedRenderer> a, b;
  std::thread t([&] { b = worker::SceneCache(dir.string(), fetch_from(other)).prepare(scene_task(hash)); });
  a = worker::SceneCache(dir.string(), fetch_from(fake)).prepare(scene_task(hash));
  t.join();
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_FALSE(fs::exists(dir / (hash + ".partial-999999999-0")));
  EXPECT_TRUE(fs::exists(live));
  EXPECT_TRUE(fs::exists(dir / hash / ".main"));
}

// A dead worker's downloads of scenes nobody asks for again went only when the same scene
// was fetched: a long farm's cache filled with them. A cache starts by removing every dead
// worker's (a live one's stays).
TEST_F(SceneCacheTest, ACacheStartsByRemovingEveryDeadWorkersDownloads) {
  const std::string other(32, 'e');
  for (const std::string& name :
       {other + ".partial-999999999-0", other + ".partial-999999999-removed-3", hash + ".partial-999999998-1"})
    fs::create_directories(dir / name / "files");
  const fs::path live = dir / (other + ".partial-" + std::to_string(::getppid()) + "-0");
  fs::create_directories(live);
  worker::SceneCache cache(dir.string(), fetch_from(fake));
  for (const fs::directory_entry& e : fs::directory_iterator(dir))
    if (e.path() != live) {
      EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
    }
  EXPECT_TRUE(fs::exists(live));
}

// A fetch onto a disk without room for the scene failed midway ("cannot write"), the cache
// never making room. It removes scenes no worker holds first (any idle time), and where the
// scene still would not fit it is refused before a byte is written, naming the sizes.
TEST_F(SceneCacheTest, AFetchMakesRoomOnAFullDiskOrSaysWhatItNeeds) {
  std::string other;
  const v1::SceneBundle second = bundle_of(testing::source_path("scenes/cornell-spheres.gltf"), &other);
  fake.scenes[other] = second;
  { worker::SceneCache(dir.string(), fetch_from(fake)).prepare(scene_task(hash)); }
  ASSERT_TRUE(fs::exists(dir / hash / ".main"));
  worker::SceneCache cache(dir.string(), fetch_from(fake));
  cache.free_disk_bytes = [&]() -> std::optional<uint64_t> {  // room only once the first scene is gone
    return fs::exists(dir / hash) ? uint64_t(0) : uint64_t(1) << 40;
  };
  ASSERT_NE(cache.prepare(scene_task(other)), nullptr);
  EXPECT_FALSE(fs::exists(dir / hash));
  EXPECT_TRUE(fs::exists(dir / other / ".main"));
  // No room at all, the one scene there held: refused, nothing written.
  worker::SceneCache full(dir.string(), fetch_from(fake));
  full.free_disk_bytes = []() -> std::optional<uint64_t> { return uint64_t(0); };
  try {
    full.prepare(scene_task(hash));
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("scene cache " + dir.string() + ": scene " + hash + " takes "),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("MiB free with every scene no worker holds removed"), std::string::npos)
        << e.what();
  }
  EXPECT_TRUE(fs::exists(dir / other / ".main"));  // (held by `cache`)
  for (const fs::directory_entry& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".partial"), std::string::npos) << e.path();
}

TEST_F(SceneCacheTest, BytesThatDoNotHashToTheSceneAreRefusedAndLeaveNothing) {
  fake.damage_scenes = true;
  const std::string why = refusal<WireError>();
  EXPECT_NE(why.find("scene " + hash + ": its bytes hash to"), std::string::npos) << why;
  EXPECT_TRUE(fs::is_empty(dir));
}

// A coordinator that stays out of reach: a few tries without a byte, then the error (the
// fetcher gives the task back with it); nothing is left half-written.
TEST_F(SceneCacheTest, ACoordinatorOutOfReachFailsTheFetchAfterAFewTries) {
  fake.scene_streams_to_cut = 100;
  fake.cut_after_pieces = 0;
  EXPECT_EQ(refusal<std::runtime_error>(), "fetch scene " + hash + ": connection lost (a test's)");
  EXPECT_EQ(fake.scene_fetches, worker::SceneCache::kFetchAttempts);
  EXPECT_TRUE(fs::is_empty(dir));
}

}  // namespace
}  // namespace tessera
