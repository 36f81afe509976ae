// KHR_lights_punctual lights and the file's camera, placed by their node's world transform
// (docs/gltf.md, Lights and Cameras), and the camera that frames a file without one.
#pragma once

#include <optional>
#include <string>

#include "core/math/transform.h"
#include "core/scene/gltf/gltf_context.h"

namespace tessera {

// The light a node's KHR_lights_punctual extension names, if the node has one.
std::optional<int> gltf_node_light(const GltfContext& ctx, const tinygltf::Node& node, const std::string& node_el);

// KHR_lights_punctual's lights[index] placed by `world`, appended to the scene's lights:
// photometric units divided by 683 lm/W.
void add_gltf_light(GltfContext& ctx, int index, const Mat4& world, const Mat4& orientation,
                    const std::string& node_el);  // orientation: place_light's

// cameras[index] placed by `world` as the scene's camera, unless an earlier node's camera
// is already (the first in the scene's node order wins); it must exist either way.
void add_gltf_camera(GltfContext& ctx, int index, const Mat4& world, const std::string& node_el);

// For a file without a camera: one looking down -Z at the bounds' centre, 40 degrees
// vertical field of view, far enough back to see the bounding sphere; with a warning.
void frame_gltf_scene(GltfContext& ctx);

}  // namespace tessera
