// Secrets the coordinator makes and checks: random values from OpenSSL's CSPRNG, and
// SHA-256 digests (only digests of tokens, credentials and worker secrets are kept).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace tessera {

// `bytes` random bytes as lowercase hex (2 x bytes characters). Throws std::runtime_error
// if the generator fails.
std::string random_hex(size_t bytes);
uint64_t random_u64();
// The raw 32-byte digest.
std::string sha256(std::string_view s);
// Equal strings, in a time that depends on their length only.
bool equal_secret(std::string_view a, std::string_view b);

}  // namespace tessera
