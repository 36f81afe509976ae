#include "core/camera/camera_path.h"

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "core/render/settings.h"
#include "core/scene/scene.h"

namespace tessera {

namespace {

using nlohmann::json;

[[noreturn]] void fail(const std::string& where, const std::string& why) {
  throw SettingsError("--camera-path", where + ": " + why);
}

double number(const json& v, const std::string& where) {
  if (!v.is_number()) fail(where, "must be a number");
  const double d = v.get<double>();
  if (!std::isfinite(d)) fail(where, "must be finite");
  return d;
}

CameraPath::Point point(const json& v, const std::string& where) {
  if (!v.is_array() || v.size() != 3) fail(where, "must be [x, y, z]");
  CameraPath::Point p;
  for (int i = 0; i < 3; ++i) {
    p[i] = number(v[i], where);
    if (std::fabs(p[i]) > Scene::kMaxCoordinate) fail(where, "coordinates must be within 1e12");
  }
  return p;
}

bool nonzero(const CameraPath::Point& p) { return p[0] != 0 || p[1] != 0 || p[2] != 0; }

Vec3 vec(const CameraPath::Point& p) { return Vec3{float(p[0]), float(p[1]), float(p[2])}; }

json point_json(const CameraPath::Point& p) { return json::array({p[0], p[1], p[2]}); }

// Interpolates one channel over the keys that set it.
template <typename Get>
std::optional<double> channel(const std::vector<CameraPath::Key>& keys, double frame, Get get) {
  std::vector<double> xs, ys;
  for (const CameraPath::Key& k : keys)
    if (const std::optional<double> v = get(k)) {
      xs.push_back(k.frame);
      ys.push_back(*v);
    }
  if (xs.empty()) return std::nullopt;
  return monotone_cubic(xs, ys, frame);
}

template <typename Get>
std::optional<CameraPath::Point> point_channel(const std::vector<CameraPath::Key>& keys, double frame, Get get) {
  CameraPath::Point out;
  for (int i = 0; i < 3; ++i) {
    const std::optional<double> v = channel(keys, frame, [&](const CameraPath::Key& k) -> std::optional<double> {
      const std::optional<CameraPath::Point> p = get(k);
      return p ? std::optional<double>((*p)[i]) : std::nullopt;
    });
    if (!v) return std::nullopt;
    out[i] = *v;
  }
  return out;
}

}  // namespace

double monotone_cubic(const std::vector<double>& xs, const std::vector<double>& ys, double x) {
  const size_t n = xs.size();
  if (x <= xs.front()) return ys.front();
  if (x >= xs.back()) return ys.back();
  // Fritsch & Carlson (1980): tangents are the mean of the neighbouring slopes (one-sided at
  // the ends), zero where the data turn, then scaled so that each segment's pair stays
  // within the circle of radius 3 (in units of its slope), which keeps every segment
  // monotone. A tangent is shared by the segments either side, so the curve is C1.
  std::vector<double> d(n - 1), m(n);
  for (size_t i = 0; i + 1 < n; ++i) d[i] = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]);
  m[0] = d[0];
  m[n - 1] = d[n - 2];
  for (size_t i = 1; i + 1 < n; ++i) m[i] = d[i - 1] * d[i] <= 0 ? 0.0 : (d[i - 1] + d[i]) / 2;
  for (size_t i = 0; i + 1 < n; ++i) {
    if (d[i] == 0) {
      m[i] = m[i + 1] = 0;
      continue;
    }
    const double a = m[i] / d[i], b = m[i + 1] / d[i], r = a * a + b * b;
    if (r > 9) {
      const double t = 3 / std::sqrt(r);
      m[i] = t * a * d[i];
      m[i + 1] = t * b * d[i];
    }
  }
  const size_t k = size_t(std::upper_bound(xs.begin(), xs.end(), x) - xs.begin()) - 1;  // xs[k] <= x < xs[k+1]
  const double h = xs[k + 1] - xs[k], t = (x - xs[k]) / h;
  const double t2 = t * t, t3 = t2 * t;
  return (2 * t3 - 3 * t2 + 1) * ys[k] + (t3 - 2 * t2 + t) * h * m[k] + (-2 * t3 + 3 * t2) * ys[k + 1] +
         (t3 - t2) * h * m[k + 1];
}

CameraPath::Key CameraPath::key_at(double frame) const {
  Key k;
  k.frame = frame;
  k.eye = point_channel(keys, frame, [](const Key& key) { return key.eye; });
  k.target = point_channel(keys, frame, [](const Key& key) { return key.target; });
  k.up = point_channel(keys, frame, [](const Key& key) { return key.up; });
  k.fov = channel(keys, frame, [](const Key& key) { return key.fov; });
  k.lens_radius = channel(keys, frame, [](const Key& key) { return key.lens_radius; });
  k.focal_distance = channel(keys, frame, [](const Key& key) { return key.focal_distance; });
  for (const Key& key : keys)  // steps: the last key at or before the frame, else the first
    if (key.max_depth && (!k.max_depth || key.frame <= frame)) k.max_depth = key.max_depth;
  return k;
}

CameraPath::At CameraPath::at(double frame) const {
  const Key k = key_at(frame);
  At a;
  const auto point = [](const std::optional<Point>& p) { return p ? std::optional<Vec3>(vec(*p)) : std::nullopt; };
  const auto scalar = [](const std::optional<double>& v) { return v ? std::optional<float>(float(*v)) : std::nullopt; };
  a.eye = point(k.eye);
  a.target = point(k.target);
  a.up = point(k.up);
  a.fov = scalar(k.fov);
  a.lens_radius = scalar(k.lens_radius);
  a.focal_distance = scalar(k.focal_distance);
  a.max_depth = k.max_depth;
  if (turntable) {
    a.orbit = true;
    a.orbit_angle = float(2 * M_PI * std::fmod((frame - turntable->start) / turntable->frames, 1.0));
    a.orbit_axis = normalize(vec(turntable->axis));
    if (turntable->center) a.orbit_center = vec(*turntable->center);
  }
  return a;
}

CameraPath CameraPath::for_frame(double frame) const {
  CameraPath p;
  if (!keys.empty()) p.keys.push_back(key_at(frame));
  p.turntable = turntable;
  return p;
}

CameraPath CameraPath::parse(const std::string& text) {
  if (text.size() > kMaxBytes) fail("file", "larger than 1 MiB");
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    fail("file", std::string("not JSON: ") + e.what());
  }
  if (!j.is_object()) fail("file", "must be a JSON object with \"keys\" and/or \"turntable\"");
  CameraPath path;
  for (const auto& [name, v] : j.items())
    if (name != "keys" && name != "turntable") fail(name, "unknown field (known: keys, turntable)");
  if (j.contains("keys")) {
    const json& ks = j["keys"];
    if (!ks.is_array()) fail("keys", "must be a list");
    if (ks.size() > kMaxKeys) fail("keys", "at most " + std::to_string(kMaxKeys));
    for (size_t i = 0; i < ks.size(); ++i) {
      const std::string at = "key " + std::to_string(i + 1);
      const json& k = ks[i];
      if (!k.is_object()) fail(at, "must be an object");
      if (!k.contains("frame")) fail(at, "has no frame");
      Key key;
      for (const auto& [name, v] : k.items()) {
        const std::string where = at + " " + name;
        if (name == "frame") {
          key.frame = number(v, where);
        } else if (name == "eye") {
          key.eye = point(v, where);
        } else if (name == "target") {
          key.target = point(v, where);
        } else if (name == "up") {
          key.up = point(v, where);
          if (!nonzero(*key.up)) fail(where, "must not be zero");
        } else if (name == "fov") {
          key.fov = number(v, where);
          if (*key.fov <= 0 || *key.fov >= 180) fail(where, "must be between 0 and 180 degrees");
        } else if (name == "lens_radius") {
          key.lens_radius = number(v, where);
          if (*key.lens_radius < 0 || *key.lens_radius > Scene::kMaxCoordinate) fail(where, "must be in 0..1e12");
        } else if (name == "focal_distance") {
          key.focal_distance = number(v, where);
          if (*key.focal_distance <= 0 || *key.focal_distance > Scene::kMaxCoordinate)
            fail(where, "must be > 0 and at most 1e12");
        } else if (name == "max_depth") {
          if (!v.is_number_integer() || v.get<int64_t>() < 0 || v.get<int64_t>() > RenderSettings::kMaxDepth)
            fail(where, "must be a whole number in 0.." + std::to_string(RenderSettings::kMaxDepth));
          key.max_depth = int(v.get<int64_t>());
        } else {
          fail(where, "unknown field (known: frame, eye, target, up, fov, lens_radius, focal_distance, max_depth)");
        }
      }
      if (key.eye && key.target && key.eye == key.target) fail(at, "eye and target are the same point");
      if (!path.keys.empty() && key.frame <= path.keys.back().frame)
        fail(at, "frame " + json(key.frame).dump() + " does not come after the previous key's");
      path.keys.push_back(key);
    }
  }
  if (j.contains("turntable")) {
    const json& t = j["turntable"];
    if (!t.is_object()) fail("turntable", "must be an object");
    if (!t.contains("frames")) fail("turntable", "has no frames (frames a turn takes)");
    Turntable tt;
    for (const auto& [name, v] : t.items()) {
      const std::string where = "turntable " + name;
      if (name == "frames") {
        tt.frames = number(v, where);
        if (tt.frames == 0) fail(where, "must not be 0");
      } else if (name == "start") {
        tt.start = number(v, where);
      } else if (name == "axis") {
        tt.axis = point(v, where);
        if (!nonzero(tt.axis)) fail(where, "must not be zero");
      } else if (name == "center") {
        tt.center = point(v, where);
      } else {
        fail(where, "unknown field (known: frames, start, axis, center)");
      }
    }
    path.turntable = tt;
  }
  // What a farm job carries is this path written out again (1e12 becomes 1000000000000.0):
  // held to the same bound, so that the coordinator, which reads it back, accepts what the
  // client did (a 0.96 MB file rendered here and was refused at submit).
  if (const size_t n = path.to_json().size(); n > kMaxBytes)
    fail("file", "written out as a job carries it, it takes " + std::to_string(n) + " bytes, over 1 MiB");
  return path;
}

std::string CameraPath::to_json() const {
  json j = json::object();
  if (!keys.empty()) {
    json ks = json::array();
    for (const Key& k : keys) {
      json o{{"frame", k.frame}};
      if (k.eye) o["eye"] = point_json(*k.eye);
      if (k.target) o["target"] = point_json(*k.target);
      if (k.up) o["up"] = point_json(*k.up);
      if (k.fov) o["fov"] = *k.fov;
      if (k.lens_radius) o["lens_radius"] = *k.lens_radius;
      if (k.focal_distance) o["focal_distance"] = *k.focal_distance;
      if (k.max_depth) o["max_depth"] = *k.max_depth;
      ks.push_back(o);
    }
    j["keys"] = ks;
  }
  if (turntable) {
    json t{{"frames", turntable->frames}, {"start", turntable->start}, {"axis", point_json(turntable->axis)}};
    if (turntable->center) t["center"] = point_json(*turntable->center);
    j["turntable"] = t;
  }
  return j.dump();
}

}  // namespace tessera
