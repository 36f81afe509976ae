#include "core/render/settings.h"

#include <algorithm>

namespace tessera {

std::vector<std::pair<uint32_t, uint32_t>> RenderSettings::passes() const {
  std::vector<std::pair<uint32_t, uint32_t>> out;
  const uint32_t total = uint32_t(std::max(spp, 0));
  uint32_t start = 0;
  const uint32_t step = uint32_t(std::max(1, adaptive ? adaptive_batch : pass_spp));
  while (start < total) {
    uint32_t end = start + step + ((adaptive && start == 0) ? 1 : 0);
    end = std::min(end, total);
    out.emplace_back(start, end);
    start = end;
  }
  return out;
}

}  // namespace tessera
