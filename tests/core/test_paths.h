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

// Regular files under a folder (none if it is absent): what a test expects to be gone.
inline size_t files_under(const std::filesystem::path& p) {
  size_t n = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(p, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec))
    n += it->is_regular_file(ec);
  return n;
}

}  // namespace tessera::testing

#define TESSERA_REQUIRE_SHARED_SCENE(var, name)                                           \
  const std::string var = ::tessera::testing::shared_scene(name);                         \
  if (var.empty())                                                                        \
  GTEST_SKIP() << "shared CS184 scene " << name << " not found under " TESSERA_SHARED_DIR \
               << "/scenes/cs184 (the ../shared folder is absent); skipping"
