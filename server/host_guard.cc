#include "server/host_guard.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cctype>

namespace tessera {
namespace {

std::string lower_name(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (!out.empty() && out.back() == '.') out.pop_back();
  return out;
}

bool all_digits(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c); });
}

}  // namespace

bool host_allowed(std::string_view host_header, const std::vector<std::string>& allowed) {
  if (host_header.empty()) return true;
  std::string_view name = host_header;
  if (name.front() == '[') {  // [v6]:port
    const size_t close = name.find(']');
    if (close == std::string_view::npos) return false;
    const std::string_view rest = name.substr(close + 1);
    if (!rest.empty() && !(rest.front() == ':' && all_digits(rest.substr(1)))) return false;
    const std::string v6(name.substr(1, close - 1));
    in6_addr a6;
    return inet_pton(AF_INET6, v6.c_str(), &a6) == 1;
  }
  if (const size_t colon = name.rfind(':'); colon != std::string_view::npos) {
    if (!all_digits(name.substr(colon + 1))) return false;
    name = name.substr(0, colon);
  }
  const std::string host = lower_name(name);
  in_addr a4;
  if (inet_pton(AF_INET, host.c_str(), &a4) == 1) return true;  // dotted quads only
  if (host == "localhost" || (host.size() > 10 && host.ends_with(".localhost"))) return true;
  return std::any_of(allowed.begin(), allowed.end(), [&](const std::string& a) { return lower_name(a) == host; });
}

}  // namespace tessera
