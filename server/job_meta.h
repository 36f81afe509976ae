// What a job is, as submitted: the fields that a still, a sequence, each frame of a
// sequence and the job's database row share. Copied whole, never field by field.
#pragma once

#include <cstdint>
#include <string>

#include "wire.h"

namespace tessera {

struct JobMeta {
  std::string id;
  std::string name;        // the user's, or the scene file's
  std::string owner;       // the submitting token's name ("" without tokens)
  std::string scene_hash;  // the bundle's content hash (SceneStore)
  std::string main_file;   // the scene file inside the bundle
  int32_t priority = 0;
  uint64_t seq = 0;             // submission order
  uint64_t scene_bytes = 0;     // the bundle's, counted against the owner's limit
  double submitted_at = 0;      // wall clock, seconds since 1970 (0: a job of an older database)
  v1::RenderSettings settings;  // as on the wire; a frame's carries its frame number
};

}  // namespace tessera
