// A ray with its parametric interval: what cameras make and the accelerator traces.
#pragma once

#include "core/math/vec.h"

namespace tessera {

struct Ray {
  Vec3 o, d;
  float tmin = 0, tmax = 1e30f;
};

}  // namespace tessera
