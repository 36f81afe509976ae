// Draco decoding behind a shared library of our own (libtessera_draco.so), so that no
// executable links libdraco.so directly: libdraco exports a tinygltf of its own (its glTF
// I/O, another version) whose symbols, met first, would stand in for Debian's libtinygltf
// (a test binary that linked Draco first crashed inside tinygltf). Loaded as a dependency
// of this shim, libdraco comes after every library an executable names, so lookups find
// Debian's tinygltf first; and the link never resolves through an indirect dependency.
// Plain types only cross this boundary.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace tessera {

struct DracoMesh {
  size_t points = 0;
  std::vector<uint32_t> indices;  // 3 per face, each below `points`
  struct Attribute {
    int components = 0;
    std::vector<float> values;  // points x components, normalized integers scaled as Draco says
  };
  std::map<uint32_t, Attribute> attributes;  // by Draco unique id
};

// Decodes a Draco mesh; false with `error` set when the bytes do not decode or hold more
// than `max_points` points.
bool decode_draco_mesh(const char* data, size_t size, size_t max_points, DracoMesh* out, std::string* error);

}  // namespace tessera
