// The Referee the coordinator uses (verifier.h): the task's scene, loaded from the
// SceneStore's copy on disk, rendered by this process exactly as a worker would.
#pragma once

#include "server/scene_store.h"
#include "server/verifier.h"

namespace tessera {

Referee local_referee(const SceneStore& scenes);

}  // namespace tessera
