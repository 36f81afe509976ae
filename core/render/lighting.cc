#include "core/render/lighting.h"

#include <cstdio>
#include <map>
#include <utility>

namespace tessera {
namespace {

// A light kind's name, singular and plural.
std::pair<const char*, const char*> kind_name(Light::Kind k) {
  switch (k) {
    case Light::Kind::kRect:
      return {"area light", "area lights"};
    case Light::Kind::kMesh:
    case Light::Kind::kSphere:
      return {"emissive surface sampled as a light", "emissive surfaces sampled as lights"};
    case Light::Kind::kPoint:
      return {"point light", "point lights"};
    case Light::Kind::kSpot:
      return {"spot light", "spot lights"};
    case Light::Kind::kDirectional:
      return {"directional light", "directional lights"};
    case Light::Kind::kAmbient:
      return {"ambient light", "ambient lights"};
    case Light::Kind::kEnvironment:
      return {"environment", "environments"};
  }
  return {"light", "lights"};
}

}  // namespace

std::string describe_lighting(const Scene& scene, const RenderSettings& s) {
  std::map<std::string, size_t> kinds;  // (meshes and spheres that emit share a name)
  for (const Light& l : scene.lights) ++kinds[kind_name(l.kind).first];
  std::string out;
  auto add = [&out](const std::string& part) { out += (out.empty() ? "" : ", ") + part; };
  for (const Light& l : scene.lights) {
    auto it = kinds.find(kind_name(l.kind).first);
    if (it == kinds.end()) continue;  // counted already
    add(std::to_string(it->second) + " " + (it->second == 1 ? kind_name(l.kind).first : kind_name(l.kind).second));
    kinds.erase(it);
  }
  // Glow: emissive shapes that are not lights (below Scene::kLampRadiance).
  size_t glow = 0;
  for (const Mesh& m : scene.meshes)
    if (m.light < 0 && scene.materials[m.material].emits()) ++glow;
  for (const Sphere& sp : scene.spheres)
    if (sp.light < 0 && scene.materials[sp.material].emits()) ++glow;
  if (glow) {
    char limit[32];
    std::snprintf(limit, sizeof limit, "%g", double(Scene::kLampRadiance));
    add(std::to_string(glow) + (glow == 1 ? " glowing surface" : " glowing surfaces") +
        " (emission below a mean radiance of " + limit + ": seen and reflected, not sampled as a light)");
  }
  char strength[48] = "";
  if (s.environment_strength != 1)
    std::snprintf(strength, sizeof strength, " x strength %g", double(s.environment_strength));
  if (!s.environment_map.empty()) {
    add("the environment map " + s.environment_map + strength);
  } else if (s.environment) {
    char c[96];
    std::snprintf(c, sizeof c, "a uniform environment of radiance (%g, %g, %g)", double(s.environment->r),
                  double(s.environment->g), double(s.environment->b));
    add(c + std::string(strength));
  } else if (scene.unlit && s.default_environment) {
    add("the default environment (uniform radiance 1" + std::string(strength) + "), as the scene has no light");
  }
  if (out.empty())  // (a glTF scene without lights gets the default environment; a COLLADA one does not)
    return scene.unlit && !s.default_environment
               ? "none: the scene has no light and --no-default-env is set, so the image is black"
               : "none: the scene has no light, so the image is black";
  return out;
}

void print_scene_notes(const Scene& scene, const RenderSettings& s, std::FILE* to) {
  // An unlit scene's warning (its first) says what the default environment does: moot
  // when the user gave an environment.
  const bool lit_by_flags = s.environment || !s.environment_map.empty();
  // ... and wrong without the default environment (--no-default-env): the lighting line says so.
  for (size_t i = scene.unlit && (lit_by_flags || !s.default_environment) ? 1 : 0; i < scene.warnings.size(); ++i)
    std::fprintf(to, "tessera: warning: %s\n", scene.warnings[i].c_str());
  std::fprintf(to, "tessera: lighting: %s\n", describe_lighting(scene, s).c_str());
}

}  // namespace tessera
