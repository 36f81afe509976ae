#include "core/scene/animation.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>

#include "core/scene/scene.h"
#include "core/scene/scene_error.h"

namespace tessera {

size_t SceneAnimation::find_clip(const std::string& selector) const {
  if (clips.empty()) throw std::invalid_argument("the scene has no animations");
  if (selector.empty()) return 0;
  for (size_t i = 0; i < clips.size(); ++i)
    if (clips[i].name == selector) return i;
  if (selector.find_first_not_of("0123456789") == std::string::npos && selector.size() < 9) {
    const size_t i = std::stoul(selector);
    if (i < clips.size()) return i;
  }
  std::string known;
  for (size_t i = 0; i < clips.size(); ++i)
    known += (i ? ", " : "") + std::to_string(i) + (clips[i].name.empty() ? "" : " '" + clips[i].name + "'");
  throw std::invalid_argument("no animation '" + selector + "' (the scene has " + known + ")");
}

namespace {

using Q = std::array<double, 4>;

Q normalized(Q q) {
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (!(n > 0)) return {0, 0, 0, 1};
  for (double& v : q) v /= n;
  return q;
}

// Spherical linear interpolation along the shorter arc (glTF spec, appendix "Interpolation").
Q slerp(Q a, Q b, double t) {
  double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
  if (d < 0) {  // q and -q are the same rotation: take the shorter way
    for (double& v : b) v = -v;
    d = -d;
  }
  Q out;
  if (d > 0.9995) {  // nearly parallel: lerp avoids dividing by sin(0)
    for (int i = 0; i < 4; ++i) out[size_t(i)] = a[size_t(i)] + t * (b[size_t(i)] - a[size_t(i)]);
    return normalized(out);
  }
  const double theta = std::acos(std::min(1.0, d)), s = std::sin(theta);
  const double wa = std::sin((1 - t) * theta) / s, wb = std::sin(t * theta) / s;
  for (int i = 0; i < 4; ++i) out[size_t(i)] = wa * a[size_t(i)] + wb * b[size_t(i)];
  return normalized(out);
}

// glTF's cubic spline between keys k and k + 1 at t in [0, 1] (spec, appendix C):
// p(t) = (2t^3 - 3t^2 + 1) v_k + td (t^3 - 2t^2 + t) b_k + (-2t^3 + 3t^2) v_k+1 + td (t^3 - t^2) a_k+1,
// b_k the out-tangent of key k and a_k+1 the in-tangent of key k+1, td the keys' interval.
double hermite(double vk, double bk, double vk1, double ak1, double t, double td) {
  const double t2 = t * t, t3 = t2 * t;
  return (2 * t3 - 3 * t2 + 1) * vk + td * (t3 - 2 * t2 + t) * bk + (-2 * t3 + 3 * t2) * vk1 + td * (t3 - t2) * ak1;
}

}  // namespace

std::vector<double> sample_weights(const SceneAnimation::Channel& c, double time) {
  using I = SceneAnimation::Interpolation;
  const size_t n = c.width, keys = c.times.size();
  const bool cubic = c.interpolation == I::kCubicSpline;
  auto at = [&](size_t k, size_t i, size_t part = 1) { return c.values[(cubic ? 3 * k + part : k) * n + i]; };
  std::vector<double> v(n);
  if (time <= c.times.front() || keys == 1 || time >= c.times.back()) {
    const size_t k = time >= c.times.back() ? keys - 1 : 0;
    for (size_t i = 0; i < n; ++i) v[i] = at(k, i);
    return v;
  }
  const size_t k = size_t(std::upper_bound(c.times.begin(), c.times.end(), time) - c.times.begin()) - 1;
  const double td = c.times[k + 1] - c.times[k], t = (time - c.times[k]) / td;
  for (size_t i = 0; i < n; ++i) switch (c.interpolation) {
      case I::kStep:
        v[i] = at(k, i);
        break;
      case I::kLinear:
        v[i] = at(k, i) + t * (at(k + 1, i) - at(k, i));
        break;
      case I::kCubicSpline:
        v[i] = hermite(at(k, i), at(k, i, 2), at(k + 1, i), at(k + 1, i, 0), t, td);
        break;
    }
  return v;
}

std::array<double, 4> sample_channel(const SceneAnimation::Channel& c, double time) {
  using I = SceneAnimation::Interpolation;
  const size_t n = c.path == SceneAnimation::Path::kRotation ? 4 : 3;
  const size_t keys = c.times.size();
  const bool cubic = c.interpolation == I::kCubicSpline;
  // Key k's value (the middle of its in-tangent, value, out-tangent triple when cubic).
  auto value = [&](size_t k, size_t part = 1) {
    std::array<double, 4> v{0, 0, 0, 0};
    const size_t at = cubic ? (3 * k + part) * n : k * n;
    for (size_t i = 0; i < n; ++i) v[i] = c.values[at + i];
    return v;
  };
  auto finish = [&](std::array<double, 4> v) { return n == 4 ? normalized(v) : v; };
  if (time <= c.times.front() || keys == 1) return finish(value(0));
  if (time >= c.times.back()) return finish(value(keys - 1));
  const size_t k = size_t(std::upper_bound(c.times.begin(), c.times.end(), time) - c.times.begin()) - 1;
  const double td = c.times[k + 1] - c.times[k], t = (time - c.times[k]) / td;
  switch (c.interpolation) {
    case I::kStep:
      return finish(value(k));
    case I::kLinear: {
      const auto a = value(k), b = value(k + 1);
      if (n == 4) return slerp(a, b, t);
      std::array<double, 4> v{};
      for (size_t i = 0; i < n; ++i) v[i] = a[i] + t * (b[i] - a[i]);
      return v;
    }
    case I::kCubicSpline: {
      const auto vk = value(k), bk = value(k, 2), vk1 = value(k + 1), ak1 = value(k + 1, 0);
      std::array<double, 4> v{};
      for (size_t i = 0; i < n; ++i) v[i] = hermite(vk[i], bk[i], vk1[i], ak1[i], t, td);
      return finish(v);
    }
  }
  return finish(value(k));
}

Mat4 trs_matrix(const std::array<double, 3>& t, const std::array<double, 4>& q, const std::array<double, 3>& s) {
  const std::array<double, 4> r = normalized(q);
  const double x = r[0], y = r[1], z = r[2], w = r[3];
  const Mat4 rot =
      Mat4::from_row_major({1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), 0, 2 * (x * y + z * w),
                            1 - 2 * (x * x + z * z), 2 * (y * z - x * w), 0, 2 * (x * z - y * w), 2 * (y * z + x * w),
                            1 - 2 * (x * x + y * y), 0, 0, 0, 0, 1});
  return Mat4::translate(t[0], t[1], t[2]) * rot * Mat4::scale(s[0], s[1], s[2]);
}

// (Directions unit in double where float's squares over- or underflow: a node scaled by
// 1e20 gave a zero direction that passed as finite, a light shining nowhere.)
void place_camera(CameraDesc& d, const Mat4& w) {
  d.eye = w.point(0, 0, 0).to_float();
  d.forward = unit(w.vector(0, 0, -1));
  d.up = unit(w.vector(0, 1, 0));
  d.cs184_dir = -d.forward;
}

Mat4 orientation_of(bool trs, const std::array<double, 4>& rotation, const Mat4& matrix) {
  return trs ? trs_matrix({0, 0, 0}, rotation, {1, 1, 1}) : matrix;
}

void place_light(Light& l, const Mat4& w, const Mat4& orientation) {
  Vec3 aim = unit(w.vector(0, 0, -1));
  if (aim == Vec3{}) aim = unit(orientation.vector(0, 0, -1));  // scaled to zero: its rotation's
  if (l.kind == Light::Kind::kDirectional) {
    l.direction = -aim;
    return;
  }
  l.position = w.point(0, 0, 0).to_float();
  if (l.kind == Light::Kind::kSpot) l.direction = aim;
}

bool placed(const Light& l) {
  const bool aimed = l.kind == Light::Kind::kDirectional || l.kind == Light::Kind::kSpot;
  return is_finite(l.position) && is_finite(l.direction) && !(aimed && l.direction == Vec3{});
}

namespace {

// Each node entry's world transform at `time`, without its scales (place_light), and
// whether the clip moves it.
struct NodeTransforms {
  std::vector<Mat4> world, orientation;
  std::vector<bool> moved;
};
NodeTransforms node_transforms(const SceneAnimation& a, const SceneAnimation::Clip& clip, double time) {
  NodeTransforms n;
  n.world.resize(a.nodes.size());
  n.orientation.resize(a.nodes.size());
  n.moved.assign(a.nodes.size(), false);
  // The clip's transform channels by node, and each animated node's local transform once
  // however often the node graph visits it (each entry scanned every channel: a graph of a
  // million entries took seconds a frame).
  std::unordered_map<uint32_t, std::vector<const SceneAnimation::Channel*>> by_node;
  for (const SceneAnimation::Channel& c : clip.channels)
    if (c.path != SceneAnimation::Path::kWeights) by_node[c.gltf_node].push_back(&c);
  std::unordered_map<uint32_t, Mat4> posed;
  for (size_t i = 0; i < a.nodes.size(); ++i) {
    const SceneAnimation::Node& node = a.nodes[i];
    Mat4 local = node.matrix;
    std::array<double, 4> rotation = node.rotation;
    bool animated = false;
    if (const auto channels = by_node.find(node.gltf_node); node.trs && channels != by_node.end()) {
      animated = true;
      const auto [at, fresh] = posed.try_emplace(node.gltf_node);
      if (fresh) {
        std::array<double, 3> t = node.translation, s = node.scale;
        std::array<double, 4> r = node.rotation;
        for (const SceneAnimation::Channel* c : channels->second) {  // (in the clip's order)
          const std::array<double, 4> v = sample_channel(*c, time);
          if (c->path == SceneAnimation::Path::kTranslation) t = {v[0], v[1], v[2]};
          if (c->path == SceneAnimation::Path::kRotation) r = v;
          if (c->path == SceneAnimation::Path::kScale) s = {v[0], v[1], v[2]};
        }
        at->second = trs_matrix(t, r, s);
      }
      local = at->second;
      for (const SceneAnimation::Channel* c : channels->second)
        if (c->path == SceneAnimation::Path::kRotation) rotation = sample_channel(*c, time);
    }
    const int32_t p = node.parent;
    n.world[i] = p >= 0 ? n.world[size_t(p)] * local : local;
    const Mat4 turn = orientation_of(node.trs, rotation, node.matrix);
    n.orientation[i] = p >= 0 ? n.orientation[size_t(p)] * turn : turn;
    n.moved[i] = animated || (p >= 0 && n.moved[size_t(p)]);
  }
  return n;
}

}  // namespace

CameraDesc pose_camera(const Scene& rest, size_t clip_index, double time) {
  CameraDesc d = rest.camera;
  const SceneAnimation& a = *rest.animation;
  if (a.camera_node < 0) return d;
  const NodeTransforms n = node_transforms(a, a.clips.at(clip_index), time);
  if (n.moved[size_t(a.camera_node)]) place_camera(d, n.world[size_t(a.camera_node)]);
  return d;
}

Scene pose_scene(const Scene& rest, size_t clip_index, double time) {
  const SceneAnimation& a = *rest.animation;
  const SceneAnimation::Clip& clip = a.clips.at(clip_index);
  const NodeTransforms n = node_transforms(a, clip, time);
  const std::vector<Mat4>& world = n.world;
  const std::vector<Mat4>& orientation = n.orientation;
  const std::vector<bool>& moved = n.moved;
  Scene s = rest;
  s.animation = rest.animation;
  auto check = [&](Vec3 v, const std::string& what) {
    if (!is_finite(v) || std::fabs(v.x) > Scene::kMaxCoordinate || std::fabs(v.y) > Scene::kMaxCoordinate ||
        std::fabs(v.z) > Scene::kMaxCoordinate)
      throw SceneError(rest.source, "animations[" + std::to_string(clip_index) + "]",
                       "at " + std::to_string(time) + " s " + what +
                           " is not finite or outside +-1e12, the range the ray tracer handles");
  };
  for (const SceneAnimation::MeshBinding& b : a.meshes) {
    const SceneAnimation::Channel* weights = nullptr;
    if (b.morph)
      for (const SceneAnimation::Channel& c : clip.channels)
        if (c.path == SceneAnimation::Path::kWeights && c.gltf_node == a.nodes[b.node].gltf_node) weights = &c;
    bool joints_moved = false;
    for (const int32_t e : b.joint_entries) joints_moved |= e >= 0 && moved[size_t(e)];
    if (!(b.skin ? joints_moved : moved[b.node]) && !weights) continue;
    Mesh& m = s.meshes[b.mesh];
    std::vector<Vec3> p = b.positions, n = b.normals;
    if (b.morph) apply_morph(*b.morph, weights ? sample_weights(*weights, time) : b.morph->weights, p, n);
    m.indices = b.indices;
    if (b.skin) {  // the joints carry the vertices; the node's own transform is ignored
      std::vector<Mat4> joints(b.joint_entries.size());
      for (size_t j = 0; j < joints.size(); ++j)
        joints[j] = b.joint_entries[j] >= 0 ? world[size_t(b.joint_entries[j])] : b.joint_rest[j];
      std::vector<Vec3> wn;
      apply_skin(*b.skin, joints, p, n, m.positions, wn);
      for (const Vec3& v : m.positions) check(v, "a vertex of mesh '" + m.name + "'");
      if (!wn.empty()) m.normals = std::move(wn);
    } else {
      const Mat4& w = world[b.node];
      for (size_t i = 0; i < p.size(); ++i) {
        m.positions[i] = w.point(p[i].x, p[i].y, p[i].z).to_float();
        check(m.positions[i], "a vertex of mesh '" + m.name + "'");
      }
      if (w.det3() < 0)  // a mirroring pose: keep geometric normals outward
        for (size_t t = 0; t + 2 < m.indices.size(); t += 3) std::swap(m.indices[t + 1], m.indices[t + 2]);
      const Mat4 nt = w.normal_matrix();
      for (size_t i = 0; i < n.size(); ++i) m.normals[i] = nt.unit_vector(n[i].x, n[i].y, n[i].z);
      const float* t4 = b.tangents.data();  // as gltf_meshes reads them
      for (size_t i = 0; i < m.tangents.size() && 4 * i < b.tangents.size(); ++i)
        m.tangents[i] = {w.unit_vector(t4[4 * i], t4[4 * i + 1], t4[4 * i + 2]),
                         (t4[4 * i + 3] < 0) != (w.det3() < 0) ? -1.0f : 1.0f};
    }
    if (n.empty() && !m.flat) m.compute_normals();  // (a flat mesh's stay zero)
  }
  for (const SceneAnimation::LightBinding& b : a.lights) {
    if (!moved[b.node]) continue;
    const Mat4& w = world[b.node];
    Light& l = s.lights[b.light];
    place_light(l, w, orientation[b.node]);
    check(l.position, "light '" + l.name + "'");
    if (!placed(l))  // (a degenerate matrix of a node the file gave as one)
      throw SceneError(rest.source, "animations[" + std::to_string(clip_index) + "]",
                       "at " + std::to_string(time) + " s light '" + l.name +
                           "' has no direction: its node's transform is degenerate");
  }
  if (a.camera_node >= 0 && moved[size_t(a.camera_node)]) {
    const Mat4& w = world[size_t(a.camera_node)];
    CameraDesc& d = s.camera;
    place_camera(d, w);
    check(d.eye, "the camera");
    if (!is_finite(d.forward) || !is_finite(d.up))
      throw SceneError(rest.source, "animations[" + std::to_string(clip_index) + "]",
                       "at " + std::to_string(time) + " s the camera's transform is degenerate");
  }
  return s;
}

}  // namespace tessera
