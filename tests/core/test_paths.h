// Where tests find the project's scenes and the shared CS184 scenes.
#pragma once

#include <filesystem>
#include <string>

namespace tessera::testing {

inline std::string source_path(const std::string& rel) { return std::string(TESSERA_SOURCE_DIR) + "/" + rel; }

// ../shared/scenes/cs184/<name>, or "" when the shared folder is absent.
inline std::string shared_scene(const std::string& name) {
  const std::string p = std::string(TESSERA_SHARED_DIR) + "/scenes/cs184/" + name;
  return std::filesystem::exists(p) ? p : std::string();
}

}  // namespace tessera::testing

#define TESSERA_REQUIRE_SHARED_SCENE(var, name)                                           \
  const std::string var = ::tessera::testing::shared_scene(name);                         \
  if (var.empty())                                                                        \
  GTEST_SKIP() << "shared CS184 scene " << name << " not found under " TESSERA_SHARED_DIR \
               << "/scenes/cs184 (the ../shared folder is absent); skipping"
