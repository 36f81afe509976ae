// What lights a render, in words, for the CLI to print before it starts: the scene's own
// lights, the emissive surfaces that are lamps (sampled) or glow (Scene::kLampRadiance),
// and the environment the settings add (--env, --env-color, or the default one of an
// unlit glTF scene). Mirrors TileRenderer::set_up_frame's choice.
#pragma once

#include <cstdio>
#include <string>

#include "core/render/settings.h"
#include "core/scene/scene.h"

namespace tessera {

std::string describe_lighting(const Scene& scene, const RenderSettings& s);

// What a user sees before a render starts, locally or through the farm: the scene's
// warnings ("tessera: warning: ...", the unlit one left out when the settings give an
// environment) and the lighting line ("tessera: lighting: ...").
void print_scene_notes(const Scene& scene, const RenderSettings& s, std::FILE* to);

}  // namespace tessera
