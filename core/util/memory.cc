#include "core/util/memory.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <sstream>

namespace tessera {
namespace {

// A whole non-negative decimal number (surrounding whitespace allowed); 0 where it is not.
uint64_t limit_in(const std::string& text) {
  std::istringstream in(text);
  std::string word;
  if (!(in >> word) || word.empty() || word.size() > 19) return 0;
  for (const char c : word)
    if (!std::isdigit(static_cast<unsigned char>(c))) return 0;
  return std::stoull(word);
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream out;
  out << in.rdbuf();
  return in ? out.str() : std::string();
}

// This process's cgroup v2 path ("0::/a/b" in /proc/self/cgroup), "" for the root.
std::string own_v2_group() {
  std::ifstream in("/proc/self/cgroup");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("0::", 0) == 0) return line.substr(3) == "/" ? std::string() : line.substr(3);
  return "";
}

}  // namespace

uint64_t memory_limit_from(uint64_t physical, const std::string& v2, const std::string& v1) {
  uint64_t m = physical;
  for (const std::string* text : {&v2, &v1})
    if (const uint64_t limit = limit_in(*text); limit > 0) m = std::min(m, limit);
  return m;
}

uint64_t usable_memory_bytes() {
  const uint64_t physical = uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGESIZE));
  std::string v2 = read_text("/sys/fs/cgroup" + own_v2_group() + "/memory.max");
  if (v2.empty()) v2 = read_text("/sys/fs/cgroup/memory.max");
  return memory_limit_from(physical, v2, read_text("/sys/fs/cgroup/memory/memory.limit_in_bytes"));
}

}  // namespace tessera
