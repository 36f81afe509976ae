// glTF animation (docs/gltf.md, docs/sequences.md): node translation, rotation, scale and
// morph weight channels with LINEAR (rotations by slerp), STEP and CUBICSPLINE interpolation, as the
// glTF 2.0 specification defines them, and the posing of a scene at a time. The loader
// fills a SceneAnimation only for files with animations: a still scene carries none and
// pays nothing.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/math/transform.h"
#include "core/math/vec.h"
#include "core/scene/deform.h"

namespace tessera {

struct Scene;
struct CameraDesc;
struct Light;

struct SceneAnimation {
  // The node hierarchy as the loader visited it (parents before children); a glTF node
  // reached twice appears twice.
  struct Node {
    uint32_t gltf_node = 0;
    int32_t parent = -1;
    bool trs = true;  // else `matrix` (glTF forbids animating a node given by a matrix)
    Mat4 matrix;
    std::array<double, 3> translation{0, 0, 0}, scale{1, 1, 1};
    std::array<double, 4> rotation{0, 0, 0, 1};  // x, y, z, w
  };
  enum class Path { kTranslation, kRotation, kScale, kWeights };
  enum class Interpolation { kLinear, kStep, kCubicSpline };
  struct Channel {
    uint32_t gltf_node = 0;
    Path path = Path::kTranslation;
    Interpolation interpolation = Interpolation::kLinear;
    std::vector<double> times;   // seconds, strictly increasing
    std::vector<double> values;  // width per key; CUBICSPLINE: in-tangent, value, out-tangent
    uint32_t width = 3;          // 3, 4 (rotation), or the morph target count (weights)
  };
  struct Clip {
    std::string name;
    std::vector<Channel> channels;
    double duration = 0;  // the last key's time
  };
  // What moves with a node: a mesh's object-space geometry, a light, the camera.
  struct MeshBinding {
    uint32_t mesh = 0, node = 0;
    std::vector<Vec3> positions, normals;  // object space; normals empty unless the file gave them
    std::vector<float> tangents;           // object space, 4 a vertex (Mesh::tangents), or empty
    std::vector<uint32_t> indices;         // as in the file (winding fixed per pose)
    // Morph targets (positions and normals above are before them), null without; a
    // weights channel on the node's glTF node animates their weights.
    std::shared_ptr<const MorphTargets> morph;
    // A skin (null without): the node's transform is then ignored and the vertices follow
    // the joints, whose node entries are `joint_entries` (-1: a joint outside the walked
    // hierarchy, held at its rest transform `joint_rest`).
    std::shared_ptr<const Skin> skin;
    std::vector<int32_t> joint_entries;
    std::vector<Mat4> joint_rest;
  };
  struct LightBinding {
    uint32_t light = 0, node = 0;
  };

  std::vector<Node> nodes;
  std::vector<Clip> clips;
  std::vector<MeshBinding> meshes;
  std::vector<LightBinding> lights;
  int32_t camera_node = -1;  // the node entry of the file's camera, if it has one

  // The clip `selector` names: its name, or its index in digits; empty: the first. Throws
  // std::invalid_argument listing the clips there are.
  size_t find_clip(const std::string& selector) const;
};

// The value of one channel at `time` (clamped to its keys): 3 or 4 numbers; rotations are
// unit quaternions (x, y, z, w).
std::array<double, 4> sample_channel(const SceneAnimation::Channel& c, double time);
// A weights channel's `width` numbers at `time` (clamped to its keys).
std::vector<double> sample_weights(const SceneAnimation::Channel& c, double time);
// Where a node's world transform puts the file's camera (eye, forward, up; CS184's
// direction) and a punctual light (position, and direction for spot and directional):
// the loader places them, and so does every pose.
void place_camera(CameraDesc& d, const Mat4& world);
// `orientation`: the node's world transform without its scales (its rotations and matrices
// alone): a spot or directional light's direction where a scale of zero (how a light is
// often hidden, and glTF says scale does not affect a light) leaves `world` none.
void place_light(Light& l, const Mat4& world, const Mat4& orientation);
// A node's local transform for `orientation`: its rotation (TRS), or its matrix.
Mat4 orientation_of(bool trs, const std::array<double, 4>& rotation, const Mat4& matrix);
// Whether place_light gave the light a finite position and, for spot and directional, a
// direction (a degenerate transform gives none).
bool placed(const Light& l);

// glTF's local transform T * R * S from a translation, a (normalized) quaternion and a scale.
Mat4 trs_matrix(const std::array<double, 3>& t, const std::array<double, 4>& r, const std::array<double, 3>& s);

// `rest` (which must have an animation) posed at `time` seconds of clip `clip`: every
// mesh, light and camera under a node the clip moves is transformed again. Throws
// SceneError when a pose puts geometry beyond the range the ray tracer handles.
Scene pose_scene(const Scene& rest, size_t clip, double time);
// The file's camera alone at `time` (pose_scene's, without posing anything else): what a
// sequence's check of every frame's camera takes.
CameraDesc pose_camera(const Scene& rest, size_t clip, double time);

}  // namespace tessera
