// Scene bundles: a scene file and every file it references, packed for the wire, named by
// a content hash, and unpacked into a folder on the receiving side. Which files a scene
// references is decided by core/scene (scene_files); this only moves bytes.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "tessera.grpc.pb.h"

namespace tessera {

using SceneFiles = google::protobuf::RepeatedPtrField<v1::SceneFile>;

// Content hash of a bundle (main file name, paths and bytes): 32 hex digits.
std::string bundle_hash(const std::string& main_file, const SceneFiles& files);
// The files a bundle of the scene at `path` holds, without their bytes: (path in the
// bundle, path on disk), the scene file first. Throws SceneError (unreadable scene) or
// std::runtime_error (a referenced file outside the scene's folder).
std::vector<std::pair<std::string, std::string>> scene_bundle_files(const std::string& path);
// Reads the scene at `path` and the files it needs. Throws SceneError (unreadable scene)
// or std::runtime_error (a referenced file outside the scene's folder or unreadable).
void pack_scene(const std::string& path, std::string* main_file, SceneFiles* files);
// Writes the bundle's files under `dir` (created) and returns the main file's path.
// Throws WireError for absolute paths, "..", or a main file that is not in the bundle.
std::string unpack_bundle(const std::string& dir, const std::string& main_file, const SceneFiles& files);

}  // namespace tessera
