// The glTF load, start to finish; each step is a unit of its own (gltf_context.h lists
// them).
#include "core/scene/gltf/gltf_loader.h"

#include <utility>

#include "core/scene/gltf/gltf_animation.h"
#include "core/scene/gltf/gltf_compression.h"
#include "core/scene/gltf/gltf_context.h"
#include "core/scene/gltf/gltf_document.h"
#include "core/scene/gltf/gltf_lights_cameras.h"
#include "core/scene/gltf/gltf_materials.h"
#include "core/scene/gltf/gltf_nodes.h"

namespace tessera {

Scene load_gltf_file(const std::string& path) {
  GltfContext ctx(path);
  parse_gltf_model(read_gltf_document(path), ctx);
  decode_gltf_compression(ctx);
  GltfMaterials materials(ctx);
  GltfAnimationBuilder animation(!ctx.model.animations.empty());
  add_gltf_nodes(ctx, materials, animation);
  Scene& scene = ctx.scene;
  if (animation.recording()) scene.animation = animation.finish(ctx);
  if (scene.meshes.empty() && scene.spheres.empty()) ctx.fail("scene", "no triangles to render");
  if (!scene.camera.present) frame_gltf_scene(ctx);
  scene.finalize();
  if (scene.lights.empty()) {  // (emissive surfaces bright enough to be lamps are lights by now)
    scene.unlit = true;
    scene.warnings.insert(
        scene.warnings.begin(),  // first: it explains the whole image
        path +
            ": no lights (no KHR_lights_punctual light, no emissive surface bright enough to light it): "
            "rendered under a "
            "neutral default environment of radiance 1 from every direction (--env-color sets "
            "another, --no-default-env none)");
  }
  return std::move(scene);
}

std::vector<std::string> gltf_external_files(const std::string& path) {
  return gltf_document_external_files(read_gltf_document(path).json);
}

}  // namespace tessera
