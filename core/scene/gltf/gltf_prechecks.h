// Our checks of a glTF file's JSON, made before tinygltf reads it and allocates anything
// (docs/gltf.md, Extensions and hostile files).
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace tessera {

// The largest file, and the largest buffer, a glTF load reads; and all its buffers together.
constexpr uint64_t kMaxGltfBufferBytes = uint64_t(1) << 30;
constexpr uint64_t kMaxGltfBuffersBytes = uint64_t(2) << 30;
// How deep a glTF's JSON may nest arrays and objects (the format's own structure needs about
// ten, extensions included; extras may hold more): deeper is refused before parsing
// (gltf_document.cc).
constexpr size_t kMaxGltfJsonDepth = 256;

// Refuses (SceneError naming `path`) a top level that is not an object, a required
// extension we do not read, a buffer without a byteLength or one over 1 GiB. An accessor
// nothing uses (no mesh, animation or skin) that tinygltf would refuse is replaced by an
// empty one, with a warning in `warnings`: viewers read accessors only when something uses
// them. Returns whether `json` changed (tinygltf must then read json.dump()).
bool precheck_gltf_json(nlohmann::json& json, const std::string& path, std::vector<std::string>& warnings);

}  // namespace tessera
