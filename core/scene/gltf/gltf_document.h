// A glTF file as read: the whole file (at most 1 GiB), a .glb's container checked (by the
// file's first bytes, not its name), and its JSON parsed, once; then, for a load,
// tinygltf's model of it, after our own checks (gltf_prechecks.h).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/scene/gltf/gltf_context.h"

namespace tessera {

struct GltfDocument {
  std::string bytes;    // the whole file
  bool binary = false;  // a GLB: the JSON is its chunk 0
  nlohmann::json json;  // the JSON, parsed by nlohmann
};

// Throws SceneError naming `path`: a file that cannot be read or is over 1 GiB, a broken
// GLB header or JSON chunk, JSON that does not parse.
GltfDocument read_gltf_document(const std::string& path);

// The buffers and images the document names outside its file, as paths relative to its
// folder, percent-decoded, each once; data: URIs are inside the file.
std::vector<std::string> gltf_document_external_files(const nlohmann::json& json);

// The pre-checks on doc.json, then tinygltf's model of the file into ctx.model: external
// files read only from inside the scene's folder and under 1 GiB, images kept encoded
// (gltf_textures.h decodes those a material uses). Warnings go to ctx.scene.warnings;
// errors throw SceneError.
void parse_gltf_model(GltfDocument doc, GltfContext& ctx);

}  // namespace tessera
