#include "server/secrets.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/rand.h>

#include <stdexcept>
#include <vector>

namespace tessera {
namespace {

void random_bytes(unsigned char* out, size_t n) {
  if (RAND_bytes(out, int(n)) != 1) throw std::runtime_error("OpenSSL's random generator failed");
}

}  // namespace

std::string random_hex(size_t bytes) {
  std::vector<unsigned char> raw(bytes);
  random_bytes(raw.data(), raw.size());
  static const char* kHex = "0123456789abcdef";
  std::string s;
  s.reserve(2 * bytes);
  for (unsigned char c : raw) s += {kHex[c >> 4], kHex[c & 15]};
  return s;
}

uint64_t random_u64() {
  uint64_t r = 0;
  random_bytes(reinterpret_cast<unsigned char*>(&r), sizeof r);
  return r;
}

std::string sha256(std::string_view s) {
  unsigned char d[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  EVP_Digest(s.data(), s.size(), d, &n, EVP_sha256(), nullptr);
  return std::string(reinterpret_cast<const char*>(d), n);
}

bool equal_secret(std::string_view a, std::string_view b) {
  return a.size() == b.size() && CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

}  // namespace tessera
