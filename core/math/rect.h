// A rectangle of pixels, in image coordinates (row 0 is the top row).
#pragma once

#include <cstdint>

namespace tessera {

struct Rect {
  int x = 0, y = 0, w = 0, h = 0;
  int64_t area() const { return int64_t(w) * h; }
  bool operator==(const Rect&) const = default;
};

}  // namespace tessera
