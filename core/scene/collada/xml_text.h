// A COLLADA file's text as its loader reads it: where an element is (its line), and the
// numbers in an element's text.
//
// Lines come from a sparse index of the file (the newlines before each 4 KiB block, built
// once), so each error or warning costs a few KiB of scanning however many there are: a
// scan from the file's start each time made a file of many warned-of nodes load in time
// growing with the square of its size. An element's text is every text and CDATA child
// joined, so a comment inside a list of numbers is skipped (the format ignores comments)
// rather than ending the list there.
#pragma once

#include <cstddef>
#include <cstdint>
#include <pugixml.hpp>
#include <string>
#include <vector>

namespace tessera {

class XmlText {
 public:
  XmlText(const std::string& text, std::string file);

  const std::string& file() const { return file_; }
  // The line (from 1) at a byte offset of the text; 0 for a negative offset.
  size_t line_of(ptrdiff_t offset) const;
  // "<name id="...">" (line N)": an element as errors and warnings name it.
  std::string where(pugi::xml_node n) const;
  // Throws SceneError naming the file and the element.
  [[noreturn]] void fail(pugi::xml_node n, const std::string& reason) const;

  // The element's text as numbers separated by white space; each finite, else fail().
  std::vector<double> numbers(pugi::xml_node n) const;
  // The first `want` of them; fail() if there are fewer.
  std::vector<double> numbers_exact(pugi::xml_node n, size_t want) const;
  // The element's text as whole numbers in [0, 2^32).
  std::vector<uint32_t> indices(pugi::xml_node n) const;
  // An attribute as a whole number in [0, max]; fail() naming it if it is missing (and
  // `fallback` < 0), not a whole number or out of range.
  uint64_t whole_attribute(pugi::xml_node n, const char* name, uint64_t max, long long fallback = -1) const;
  // %g: how numbers appear in messages.
  static std::string short_number(double v);

 private:
  static constexpr size_t kBlock = 4096;
  // The element's text: its one text child's in place, or its text and CDATA children's
  // joined into `joined`.
  const char* value(pugi::xml_node n, std::string* joined) const;
  // The element's text, token by token (white space between): `parse(s, &end)` reads a
  // value from s; a token it does not read to its end fails naming `what`; `accept(v, s)`
  // checks its range (fail()) and gives what goes in the list.
  template <typename Parse, typename Accept>
  auto tokens(pugi::xml_node n, const char* what, Parse parse, Accept accept) const;

  const std::string& text_;
  std::string file_;
  std::vector<uint32_t> newlines_before_;  // newlines before block i (a 4 GiB file has fewer than 2^32)
};

}  // namespace tessera
