// What the farm's integration tests share: where the binaries and the default scene are,
// reading a file whole, and comparing two images bit for bit.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>
#include <string>

#include "core/io/image_io.h"

namespace tessera::testing {

inline const std::string kBin = TESSERA_BIN_DIR;
inline const std::string kScene = std::string(TESSERA_SOURCE_DIR) + "/scenes/cornell-spheres.dae";

// A command's exit code and what it printed.
struct CommandResult {
  int code = -1;
  std::string out, err;
};

inline std::string slurp(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Bitwise equality of every channel (the image's five and any AOV layers), and the same
// channels in both.
inline void expect_same_pixels(const std::string& a_path, const std::string& b_path) {
  const ExrImage a = read_exr(a_path), b = read_exr(b_path);
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  EXPECT_EQ(a.x0, b.x0);  // (a crop's place in its frame: the data window)
  EXPECT_EQ(a.y0, b.y0);
  for (const char* ch : {"R", "G", "B", "spp", "variance"}) ASSERT_TRUE(a.channels.count(ch)) << ch;
  ASSERT_EQ(a.channels.size(), b.channels.size());
  for (const auto& [ch, x] : a.channels) {
    ASSERT_TRUE(b.channels.count(ch)) << ch;
    const auto& y = b.channels.at(ch);
    EXPECT_EQ(0, std::memcmp(x.data(), y.data(), x.size() * sizeof(float))) << "channel " << ch << " differs";
  }
}

}  // namespace tessera::testing
