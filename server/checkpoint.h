// A job's checkpoint file: its frame plan's state and its film, checksummed (xxh64), the
// film's sums in chunks of 65,536 pixels each encoded like a tile's sums (version 2;
// version 1, one chunk, is still read). docs/architecture.md has where and when.
#pragma once

#include <string>

#include "core/render/frame_plan.h"

namespace tessera {

struct Checkpoint {
  PlanState state;
  Film film{Rect{}};
  double elapsed = 0;  // render seconds when it was taken
};

// A checkpoint's bytes, and back (exposed for tests, the fuzzer and the benchmark).
std::string encode_checkpoint(const PlanState& state, const Film& film, double elapsed);
// Throws std::runtime_error unless the bytes are a whole, undamaged checkpoint. Without
// `with_film`, Checkpoint::film stays empty (its bytes are checksummed, not decoded).
Checkpoint decode_checkpoint(const std::string& bytes, bool with_film = true);

}  // namespace tessera
