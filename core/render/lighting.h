// What lights a render, in words, for the CLI to print before it starts: the scene's own
// lights, the emissive surfaces that are lamps (sampled) or glow (Scene::kLampRadiance),
// and the environment the settings add (--env, --env-color, or the default one of an
// unlit glTF scene). Mirrors TileRenderer::set_up_frame's choice.
#pragma once

#include <string>

#include "core/render/settings.h"
#include "core/scene/scene.h"

namespace tessera {

std::string describe_lighting(const Scene& scene, const RenderSettings& s);

}  // namespace tessera
