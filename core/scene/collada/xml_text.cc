#include "core/scene/collada/xml_text.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "core/scene/scene_error.h"

namespace tessera {
namespace {

bool space(char c) { return std::isspace(uint8_t(c)) != 0; }

// The token at s (up to white space), at most 32 bytes: what a message quotes.
std::string token(const char* s) {
  const char* e = s;
  while (*e && !space(*e) && e - s < 32) ++e;
  return std::string(s, e);
}

}  // namespace

XmlText::XmlText(const std::string& text, std::string file) : text_(text), file_(std::move(file)) {
  newlines_before_.reserve(text.size() / kBlock + 1);
  uint32_t count = 0;
  for (size_t at = 0; at < text.size(); at += kBlock) {
    newlines_before_.push_back(count);
    const char* b = text.data() + at;
    count += uint32_t(std::count(b, b + std::min(kBlock, text.size() - at), '\n'));
  }
}

size_t XmlText::line_of(ptrdiff_t offset) const {
  if (offset < 0) return 0;
  const size_t end = std::min(size_t(offset), text_.size());
  const size_t block = end / kBlock;
  if (block >= newlines_before_.size()) return 1 + (newlines_before_.empty() ? 0 : newlines_before_.back());
  const char* b = text_.data() + block * kBlock;
  return 1 + newlines_before_[block] + size_t(std::count(b, text_.data() + end, '\n'));
}

std::string XmlText::where(pugi::xml_node n) const {
  // Built by appends: `"<" + std::string(...)` trips GCC 12's false -Wrestrict (PR 105329).
  std::string s("<");
  s.append(n.name());
  if (n.attribute("id")) s.append(" id=\"").append(n.attribute("id").value()).append("\"");
  s.append("> (line ").append(std::to_string(line_of(n.offset_debug()))).append(")");
  return s;
}

void XmlText::fail(pugi::xml_node n, const std::string& reason) const { throw SceneError(file_, where(n), reason); }

const char* XmlText::value(pugi::xml_node n, std::string* joined) const {
  pugi::xml_node first = n.first_child();
  if (first && !first.next_sibling() && first.type() == pugi::node_pcdata) return first.value();
  joined->clear();
  for (pugi::xml_node c = first; c; c = c.next_sibling())
    if (c.type() == pugi::node_pcdata || c.type() == pugi::node_cdata) joined->append(c.value());
  return joined->c_str();
}

template <typename Parse, typename Accept>
auto XmlText::tokens(pugi::xml_node n, const char* what, Parse parse, Accept accept) const {
  std::vector<decltype(accept(parse(nullptr, nullptr), nullptr))> out;
  std::string joined;
  const char* s = value(n, &joined);
  while (*s) {
    while (space(*s)) ++s;
    if (!*s) break;
    char* end = nullptr;
    const auto v = parse(s, &end);
    if (end == s || (*end && !space(*end))) fail(n, std::string("'").append(token(s)).append("' is not ").append(what));
    out.push_back(accept(v, s));
    s = end;
  }
  return out;
}

std::vector<double> XmlText::numbers(pugi::xml_node n) const {
  return tokens(
      n, "a number", [](const char* s, char** end) { return std::strtod(s, end); },
      [&](double v, const char* s) {
        if (!std::isfinite(v)) fail(n, std::string("non-finite number '").append(token(s)).append("'"));
        return v;
      });
}

std::vector<double> XmlText::numbers_exact(pugi::xml_node n, size_t want) const {
  std::vector<double> v = numbers(n);
  if (v.size() < want) fail(n, "expected " + std::to_string(want) + " numbers, found " + std::to_string(v.size()));
  v.resize(want);
  return v;
}

std::vector<uint32_t> XmlText::indices(pugi::xml_node n) const {
  return tokens(
      n, "an index",
      [](const char* s, char** end) {
        errno = 0;
        return std::strtoll(s, end, 10);
      },
      [&](long long v, const char* s) {
        if (v < 0 || v > 0xFFFFFFFFll || errno == ERANGE)
          fail(n, std::string("index ").append(token(s)).append(" out of range"));
        return uint32_t(v);
      });
}

uint64_t XmlText::whole_attribute(pugi::xml_node n, const char* name, uint64_t max, long long fallback) const {
  const pugi::xml_attribute a = n.attribute(name);
  if (!a) {
    if (fallback >= 0) return uint64_t(fallback);
    fail(n, std::string("missing ") + name + " attribute");
  }
  const char* s = a.value();
  while (space(*s)) ++s;
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::isdigit(uint8_t(*s)) ? std::strtoull(s, &end, 10) : 0;
  const char* rest = end;
  while (rest && space(*rest)) ++rest;
  if (!end || end == s || *rest)
    fail(n, std::string(name).append("=\"").append(token(a.value())).append("\" is not a whole number"));
  if (errno == ERANGE || v > max)
    fail(n, std::string(name)
                .append("=\"")
                .append(token(s))
                .append("\" is over ")
                .append(std::to_string(max))
                .append(", the most this loader reads"));
  return v;
}

std::string XmlText::short_number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace tessera
