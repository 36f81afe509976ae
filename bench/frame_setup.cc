// Per-frame setup cost of a sequence (issue 12): what a worker or `tessera render --frames`
// spends before a frame's first sample. The first frame of a (scene, settings) builds the
// acceleration structure and lights; every later frame only makes its camera (with a camera
// path) and integrator, sharing them. For an animated glTF scene a later frame poses the
// scene and builds a BVH over the moving meshes only, the static ones instanced from a BVH
// built once; the figures include what a full rebuild of the pose would cost instead.
// Prints one JSON object.
//
//   tessera_frame_setup SCENE [--repeat N]
#include <chrono>
#include <cstdio>
#include <cstring>
#include <nlohmann/json.hpp>
#include <string>

#include "core/accel/accel.h"
#include "core/camera/camera_path.h"
#include "core/light/lights.h"
#include "core/render/tile_renderer.h"
#include "core/scene/animation.h"
#include "core/scene/load.h"

using namespace tessera;

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help")) {
    std::printf("usage: tessera_frame_setup SCENE [--repeat N]\n");
    return argc < 2 ? 2 : 0;
  }
  int repeat = 20;
  for (int i = 2; i + 1 < argc; ++i)
    if (!std::strcmp(argv[i], "--repeat")) repeat = std::max(1, std::atoi(argv[i + 1]));
  using clock = std::chrono::steady_clock;
  auto seconds = [](clock::time_point a) { return std::chrono::duration<double>(clock::now() - a).count(); };
  auto t0 = clock::now();
  const Scene scene = load_scene(argv[1]);
  const double load = seconds(t0);
  RenderSettings s;
  s.camera.path = std::make_shared<const CameraPath>(CameraPath::parse(
      R"({"keys": [{"frame": 0, "lens_radius": 0.05, "focal_distance": 3}, {"frame": 100, "focal_distance": 6}],
          "turntable": {"frames": 100}})"));
  double build = 1e30, frame = 1e30, set_frame = 1e30;  // best of `repeat`
  for (int r = 0; r < repeat; ++r) {
    s.frame = 0;
    t0 = clock::now();
    TileRenderer first(scene, s);
    build = std::min(build, seconds(t0));
    s.frame = r + 1;
    t0 = clock::now();
    TileRenderer next(first, s);
    frame = std::min(frame, seconds(t0));
    t0 = clock::now();
    first.set_frame(r + 2);
    set_frame = std::min(set_frame, seconds(t0));
  }
  double pose = 1e30, full = 1e30;
  if (scene.animation)
    for (int r = 0; r < repeat; ++r) {
      t0 = clock::now();
      const Scene posed = pose_scene(scene, 0, 1.0);
      pose = std::min(pose, seconds(t0));
      t0 = clock::now();
      const Accel accel(posed);
      const LightSet lights(posed);
      full = std::min(full, seconds(t0));
    }
  nlohmann::json j{{"scene", argv[1]},
                   {"triangles_and_spheres", scene.triangle_count() + scene.spheres.size()},
                   {"load_seconds", load},
                   {"first_frame_setup_seconds", build},
                   {"next_frame_setup_seconds", frame},
                   {"set_frame_seconds", set_frame},
                   {"repeat", repeat}};
  if (scene.animation) {
    j["animated"] = true;
    j["pose_seconds"] = pose;
    j["full_rebuild_of_a_pose_seconds"] = full;
  }
  std::printf("%s\n", j.dump(2).c_str());
  return 0;
}
