// JSON text for answers that carry peer text (worker names, hosts, errors).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace tessera {

// JSON text that never throws: a byte that is not UTF-8 (peer text kept before names were
// cut on character boundaries) is shown as U+FFFD rather than failing the whole answer.
inline std::string lenient_dump(const nlohmann::json& j) {
  return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

}  // namespace tessera
