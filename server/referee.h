// The Referee the coordinator uses (verifier.h): the task's scene, from the SceneStore,
// unpacked into a folder of its own under `scratch_dir` (removed afterwards) and rendered
// by this process exactly as a worker would.
#pragma once

#include <string>

#include "server/scene_store.h"
#include "server/verifier.h"

namespace tessera {

Referee local_referee(const SceneStore& scenes, std::string scratch_dir);

}  // namespace tessera
