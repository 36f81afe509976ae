#include "core/util/memory.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

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

// The groups from `path` up to the hierarchy's root: "/a/b" -> "/a/b", "/a", "".
std::vector<std::string> up_from(std::string path) {
  std::vector<std::string> out;
  while (!path.empty() && path != "/") {
    out.push_back(path);
    path = path.substr(0, path.find_last_of('/'));
  }
  out.push_back("");
  return out;
}

}  // namespace

uint64_t memory_limit_from(uint64_t physical, const std::string& v2, const std::string& v1) {
  uint64_t m = physical;
  for (const std::string* text : {&v2, &v1})
    if (const uint64_t limit = limit_in(*text); limit > 0) m = std::min(m, limit);
  return m;
}

uint64_t cgroup_memory_limit(uint64_t physical, const std::string& own_groups,
                             const std::function<std::string(const std::string&)>& read) {
  uint64_t m = physical;
  std::istringstream lines(own_groups);
  for (std::string line; std::getline(lines, line);) {
    // "0::/path" (v2), or "N:controllers:/path" (v1) with memory among the controllers.
    const size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string id = line.substr(0, a), controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
    std::string file;
    if (id == "0" && controllers.empty()) {
      file = "/sys/fs/cgroup%s/memory.max";
    } else {
      std::istringstream names(controllers);
      for (std::string name; std::getline(names, name, ',');)
        if (name == "memory") file = "/sys/fs/cgroup/memory%s/memory.limit_in_bytes";
    }
    if (file.empty()) continue;
    const size_t at = file.find("%s");
    for (const std::string& group : up_from(path))  // a limit is often set on an ancestor
      m = memory_limit_from(m, read(file.substr(0, at) + group + file.substr(at + 2)), "");
  }
  return m;
}

uint64_t usable_memory_bytes() {
  const uint64_t physical = uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGESIZE));
  return cgroup_memory_limit(physical, read_text("/proc/self/cgroup"), read_text);
}

}  // namespace tessera
