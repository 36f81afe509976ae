// Conversions between the core's types and the wire protocol, shared by the coordinator,
// the worker and the CLI.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include "core/render/film.h"
#include "core/render/settings.h"
#include "tessera.grpc.pb.h"

namespace tessera {

constexpr uint32_t kProtocolVersion = 1;
constexpr size_t kBytesPerPixel = 36;  // r, g, b, lum2 (float64) + n (uint32)
// gRPC message limit for scene uploads and images.
constexpr int kMaxMessageBytes = 512 << 20;

// Input from the network that does not make sense: handled and reported, never fatal.
class WireError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

v1::RenderSettings to_proto(const RenderSettings& s);
// Throws WireError for settings out of range.
RenderSettings from_proto(const v1::RenderSettings& p);

v1::Rect to_proto(const Rect& r);
Rect from_proto(const v1::Rect& r);

// A whole file's bytes; throws std::runtime_error naming the path.
std::string read_file_bytes(const std::string& path);

// A message as JSON with proto field names and every field present (the CLI's --json and
// the status endpoint).
std::string proto_json(const google::protobuf::Message& m);

// Tile sums <-> zstd-compressed little-endian bytes (36 per pixel).
std::string encode_sums(const std::vector<PixelSums>& sums);
// Throws WireError unless the data decodes to exactly `pixels` pixels.
std::vector<PixelSums> decode_sums(const std::string& compressed, size_t pixels);

// Content hash of a scene bundle (main file name, paths and bytes): 32 hex digits.
std::string bundle_hash(const std::string& main_file, const google::protobuf::RepeatedPtrField<v1::SceneFile>& files);
// Writes the bundle's files under `dir` (created) and returns the main file's path.
// Throws WireError for absolute paths, "..", or a main file that is not in the bundle.
std::string unpack_bundle(const std::string& dir, const std::string& main_file,
                          const google::protobuf::RepeatedPtrField<v1::SceneFile>& files);
// The files a scene needs, read from disk: the scene itself (and, for formats with
// external resources, those).
void pack_scene(const std::string& path, std::string* main_file,
                google::protobuf::RepeatedPtrField<v1::SceneFile>* files);

}  // namespace tessera
