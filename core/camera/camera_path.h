// Camera paths for sequences (--camera-path FILE, --turntable FRAMES): camera parameters
// keyframed over frame numbers, and a turntable orbit, evaluated for each frame. The file is
// JSON, documented in docs/sequences.md:
//
//   {"keys": [{"frame": 1, "eye": [0, 1, 4], "target": [0, 1, 0], "fov": 40,
//              "lens_radius": 0.1, "focal_distance": 3.5},
//             {"frame": 48, "focal_distance": 6}],
//    "turntable": {"frames": 120, "start": 1, "axis": [0, 1, 0]}}
//
// Each channel (eye, target, up, fov, lens_radius, focal_distance) is interpolated over the
// keys that set it, with a monotone cubic (Fritsch-Carlson: smooth through three or more
// keys, never overshooting, so a focal distance cannot pass its keys), and held before the
// first and after the last. max_depth steps (each key's value holds until the next). A
// channel no key sets comes from the scene's camera and the flags (-b, -d, -m). The
// turntable then turns the camera (eye, direction, up) about the axis through `center`
// (default: the centre of the scene's bounds), one turn every `frames` frames.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

#include "core/math/vec.h"

namespace tessera {

struct CameraPath {
  using Point = std::array<double, 3>;
  struct Key {
    double frame = 0;
    std::optional<Point> eye, target, up;
    std::optional<double> fov;  // vertical field of view, degrees
    std::optional<double> lens_radius, focal_distance;
    std::optional<int> max_depth;
  };
  struct Turntable {
    double frames = 0;  // frames a turn takes (negative: the other way)
    double start = 0;   // the frame at angle 0
    Point axis{0, 1, 0};
    std::optional<Point> center;
  };
  std::vector<Key> keys;  // frames strictly increasing
  std::optional<Turntable> turntable;

  static constexpr size_t kMaxBytes = 1 << 20;
  static constexpr size_t kMaxKeys = 100000;

  // What one frame takes from the path; unset fields come from the scene and the flags.
  struct At {
    std::optional<Vec3> eye, target, up;
    std::optional<float> fov, lens_radius, focal_distance;
    std::optional<int> max_depth;
    bool orbit = false;
    float orbit_angle = 0;  // radians, right-handed about orbit_axis
    Vec3 orbit_axis{0, 1, 0};
    std::optional<Vec3> orbit_center;
  };
  At at(double frame) const;
  // The channels' values at `frame`, before at() rounds them to floats: a key there.
  Key key_at(double frame) const;
  // What one frame takes from the path: a key at `frame` holding key_at(frame), and the
  // turntable. Its at(frame) is this path's, bit for bit. A frame's job carries this, not
  // the whole path (its every task would carry up to 1 MiB of keys).
  CameraPath for_frame(double frame) const;

  // Parses and checks the JSON text; throws SettingsError("--camera-path", ...) naming the
  // key and field at fault.
  static CameraPath parse(const std::string& json);
  // Canonical text (what the wire carries): parse(to_json()) gives the same path.
  std::string to_json() const;
};

// Fritsch-Carlson monotone cubic through (xs[i], ys[i]) (xs strictly increasing), held
// constant outside. Exposed for tests.
double monotone_cubic(const std::vector<double>& xs, const std::vector<double>& ys, double x);

}  // namespace tessera
