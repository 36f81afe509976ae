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

// Text a peer sent that others will see (a worker's name or host, why it says a task
// failed, a job's name), cut as utf8_prefix cuts it and with its control characters (C0,
// DEL and C1: U+0080 to U+009F) each made '?': shown on a terminal (`tessera jobs`, `watch`,
// `status`) or in a log, such a character could move the cursor, rewrite what is on the
// screen or retitle the window: one peer's text could pass for another's, or for ours.
inline std::string peer_text(std::string_view s, size_t max_bytes) {
  std::string out = utf8_prefix(s, max_bytes);
  size_t n = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    const unsigned char c = static_cast<unsigned char>(out[i]);
    if (c == 0xC2 && i + 1 < out.size() && (static_cast<unsigned char>(out[i + 1]) & 0xE0) == 0x80) {
      out[n++] = '?';  // U+0080..U+009F
      ++i;
    } else {
      out[n++] = c < 0x20 || c == 0x7F ? '?' : out[i];
    }
  }
  out.resize(n);
  return out;
}

}  // namespace tessera
