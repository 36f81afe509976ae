#include "core/util/invariant.h"

#include <cstring>

#include "core/util/log.h"

namespace tessera {

void invariant_failed(const char* condition, const char* file, int line, const std::string& what) {
  const char* slash = std::strrchr(file, '/');
  const std::string where = std::string(slash ? slash + 1 : file) + ":" + std::to_string(line);
  spdlog::critical("invariant broken at {}: {} ({})", where, what, condition);
  throw InvariantError("internal error (a bug): " + what + " [" + where + "]");
}

}  // namespace tessera
