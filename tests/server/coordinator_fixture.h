// The whole coordinator driven in-process, with a fake clock: the fixture the
// coordinator_*_test.cc files share (each unit of the coordinator has its own test file
// over parts_fixture.h; these test the wiring: a job's life through the public calls).
#pragma once

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <thread>

#include "core/io/files.h"
#include "core/io/image_io.h"
#include "core/render/local_renderer.h"
#include "core/scene/load.h"
#include "scene_chunks.h"
#include "server/coordinator.h"
#include "tests/core/test_paths.h"

namespace tessera {

namespace fs = std::filesystem;

class FakeClock : public Clock {
 public:
  explicit FakeClock(double* t) : t_(t) {}
  double now() const override { return *t_; }

 private:
  double* t_;
};

inline RenderSettings job_settings() {
  RenderSettings s;
  s.camera.width = 48;
  s.camera.height = 36;
  s.spp = 10;
  s.pass_spp = 4;  // passes of 4, 4, 2
  s.max_depth = 6;
  s.seed = 3;
  s.tile_size = 16;
  return s;
}

class CoordinatorTest : public ::testing::Test {
 protected:
  double t = 1000;
  std::string dir = (fs::temp_directory_path() / ("tessera_coord_" + std::to_string(::getpid()))).string();
  std::unique_ptr<Coordinator> c;
  std::string scene_path = testing::source_path("scenes/cornell-spheres.dae");
  Scene scene = load_scene(scene_path);

  CoordinatorOptions options() const {
    CoordinatorOptions o;
    o.data_dir = dir;
    o.lease_seconds = 5;
    o.image_interval_seconds = 0;
    o.verify_fraction = 0;  // checks are random: VerifyTest turns them on
    return o;
  }
  std::string image_path(const std::string& id, const char* file) const { return dir + "/jobs/" + id + "/" + file; }
  void SetUp() override { c = std::make_unique<Coordinator>(options(), std::make_unique<FakeClock>(&t)); }
  void TearDown() override { fs::remove_all(dir); }

  v1::SubmitJobRequest request(const RenderSettings& s) {
    v1::SubmitJobRequest r;
    r.set_version(kProtocolVersion);
    std::string main;
    pack_scene(scene_path, &main, r.mutable_files());
    r.set_main_file(main);
    *r.mutable_settings() = to_proto(s);
    return r;
  }
  // The scene sent in pieces of 1000 bytes (UploadScene), as `owner`.
  v1::SceneUpload upload(const std::string& owner = "") {
    const auto files = scene_bundle_files(scene_path);
    const SceneSource s = scene_source(files[0].first, files);
    std::vector<v1::SceneChunk> msgs(1);
    *msgs[0].mutable_manifest() = s.manifest;
    send_pieces(s, 0, 0, 1000, [&](v1::SceneChunk& piece) {
      msgs.push_back(piece);
      return true;
    });
    size_t i = 0;
    return c->upload_scene(
        [&](v1::SceneChunk* m) {
          if (i == msgs.size()) return false;
          *m = msgs[i++];
          return true;
        },
        owner);
  }
  // A job naming an upload instead of carrying its scene.
  static v1::SubmitJobRequest request(const RenderSettings& s, const v1::SceneUpload& up) {
    v1::SubmitJobRequest r;
    r.set_version(kProtocolVersion);
    r.set_upload_id(up.upload_id());
    *r.mutable_settings() = to_proto(s);
    return r;
  }
  uint64_t worker() {
    v1::RegisterRequest r;
    r.set_version(kProtocolVersion);
    r.set_name("test");
    return c->register_worker(r).worker_id();
  }
  v1::TaskResult render_task(const v1::Task& task, uint64_t worker_id) {
    const TileRenderer r(scene, from_proto(task.settings()));
    const Rect tile = from_proto(task.tile());
    const auto* mask = task.active().empty() ? nullptr : reinterpret_cast<const uint8_t*>(task.active().data());
    TileStats stats;
    std::vector<SplatRecord> splats;  // a frame tracing light paths: as a worker sends them
    const auto sums = r.render_passes(tile, {{task.sample_begin(), task.sample_end()}}, nullptr, mask, &stats, nullptr,
                                      nullptr, r.light_tracing() ? &splats : nullptr);
    v1::TaskResult res;
    res.set_worker_id(worker_id);
    res.set_task_id(task.task_id());
    res.set_raw_size(uint32_t(sums.size() * kBytesPerPixel));
    res.set_sums_zstd(encode_sums(sums));
    if (!splats.empty()) res.set_splats_zstd(encode_splats(splats));
    res.set_samples(stats.samples);
    res.set_render_seconds(0.01);
    return res;
  }
  // Runs the job to the end with one worker, in task order.
  void drain(uint64_t w) {
    for (int guard = 0; guard < 100000; ++guard) {
      const v1::GetTaskResponse r = c->get_task(w);
      if (r.tasks_size() == 0) return;
      ASSERT_TRUE(c->submit_result(render_task(r.tasks(0), w)).accepted());
    }
  }
  Film local(const RenderSettings& s) { return render_image(TileRenderer(scene, s), 2).film; }
};

inline bool same_film_as_exr(const Film& film, const ExrImage& img) {
  if (img.width != film.width() || img.height != film.height()) return false;
  for (size_t i = 0; i < film.pixels().size(); ++i) {
    const Rgb m = film.pixels()[i].mean();
    if (std::memcmp(&m.r, &img.channels.at("R")[i], 4) || std::memcmp(&m.g, &img.channels.at("G")[i], 4) ||
        std::memcmp(&m.b, &img.channels.at("B")[i], 4) || img.channels.at("spp")[i] != float(film.pixels()[i].n))
      return false;
  }
  return true;
}

// FNV-1a over the EXR's R, G, B and spp channels.
inline uint64_t exr_hash(const ExrImage& img) {
  uint64_t h = 1469598103934665603ull;
  for (const char* c : {"R", "G", "B", "spp"})
    for (float v : img.channels.at(c)) {
      const auto* b = reinterpret_cast<const unsigned char*>(&v);
      for (size_t i = 0; i < sizeof v; ++i) h = (h ^ b[i]) * 1099511628211ull;
    }
  return h;
}

// Takes the coordinator down without a word (as kill -9 would: nothing is written on the
// way out) and starts a new one on the same data folder.
// The code of the RequestError f() throws (a failure if it throws none).
template <typename F>
inline RequestError::Code refused(F&& f) {
  try {
    f();
  } catch (const RequestError& e) {
    return e.code();
  }
  ADD_FAILURE() << "not refused";
  return RequestError::Code::kInvalidArgument;
}

inline void restart(std::unique_ptr<Coordinator>& c, const CoordinatorOptions& o, double* t) {
  c.reset();
  c = std::make_unique<Coordinator>(o, std::make_unique<FakeClock>(t));
}

}  // namespace tessera
