// Cutting text that came from a peer: at most `max_bytes`, never inside a UTF-8 character,
// so that what is kept stays valid UTF-8 wherever it goes next (a protobuf string field, a
// JSON dump, a log line). A cut through a character drops that character's first bytes
// too; bytes that were not UTF-8 to begin with are left as they are.
#pragma once

#include <string>
#include <string_view>

namespace tessera {

inline std::string utf8_prefix(std::string_view s, size_t max_bytes) {
  if (s.size() <= max_bytes) return std::string(s);
  size_t n = max_bytes;
  // Back over continuation bytes (10xxxxxx) to the start of the character the cut falls in
  // (at most three: a character is at most four bytes).
  for (int k = 0; k < 3 && n > 0 && (static_cast<unsigned char>(s[n]) & 0xC0) == 0x80; ++k) --n;
  return std::string(s.substr(0, n));
}

}  // namespace tessera
