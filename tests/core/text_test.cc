// Peer text cut on character boundaries (core/util/text.h) and totals that saturate
// (core/util/saturating.h): what the coordinator's bounds rely on.
#include "core/util/text.h"

#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "core/util/saturating.h"

namespace tessera {
namespace {

TEST(Utf8Prefix, ACutNeverFallsInsideACharacter) {
  EXPECT_EQ(utf8_prefix("abc", 5), "abc");
  EXPECT_EQ(utf8_prefix("abc", 2), "ab");
  EXPECT_EQ(utf8_prefix("", 0), "");
  const std::string e = "\xC3\xA9";              // é: two bytes
  const std::string euro = "\xE2\x82\xAC";       // €: three
  const std::string smile = "\xF0\x9F\x98\x80";  // U+1F600: four
  EXPECT_EQ(utf8_prefix("a" + e, 2), "a");       // not "a\xC3"
  EXPECT_EQ(utf8_prefix("a" + e, 3), "a" + e);
  for (size_t keep = 1; keep < 4; ++keep) EXPECT_EQ(utf8_prefix("a" + euro + "b", keep), "a") << keep;
  EXPECT_EQ(utf8_prefix("a" + euro + "b", 4), "a" + euro);
  for (size_t keep = 1; keep < 5; ++keep) EXPECT_EQ(utf8_prefix("a" + smile, keep), "a") << keep;
  // The coordinator's 256-byte names: 255 ASCII bytes and then a two-byte character.
  EXPECT_EQ(utf8_prefix(std::string(255, 'a') + e, 256), std::string(255, 'a'));
  // Bytes that were never UTF-8 (a run of continuation bytes) are cut where asked, at most
  // three bytes earlier: nothing loops or underflows.
  EXPECT_EQ(utf8_prefix(std::string(10, '\x80'), 6).size(), 3u);
  EXPECT_EQ(utf8_prefix(std::string(10, '\x80'), 2).size(), 0u);
}

// A peer's text loses its control characters (each a '?'), C1 ones in UTF-8 too, and keeps
// everything else, cut as utf8_prefix cuts it.
TEST(PeerText, ControlCharactersBecomeQuestionMarks) {
  EXPECT_EQ(peer_text("\x1b]0;title\x07\x1b[2Jw\r\n\t\x7f", 100), "?]0;title??[2Jw????");
  EXPECT_EQ(peer_text("a\xc2\x9b"
                      "31mb\xc2\x80\xc2\x9f",
                      100),
            "a?31mb??");  // C1: CSI, U+0080, U+009F
  EXPECT_EQ(peer_text("caf\xc3\xa9 \xe6\x97\xa5 \xf0\x9f\x8e\xa8 \xc2\xa0", 100),
            "caf\xc3\xa9 \xe6\x97\xa5 \xf0\x9f\x8e\xa8 \xc2\xa0");  // U+00A0 and up stay
  EXPECT_EQ(peer_text("ab\x1b"
                      "cd",
                      3),
            "ab?");
  EXPECT_EQ(peer_text("x\xe6\x97\xa5", 3), "x");  // the cut, as utf8_prefix's
  EXPECT_EQ(peer_text(std::string("a\0b", 3), 10), "a?b");
}

TEST(Saturating, SumsAndProductsStopAtTheMaximum) {
  constexpr uint64_t kMax = std::numeric_limits<uint64_t>::max();
  EXPECT_EQ(saturating_add(2, 3), 5u);
  EXPECT_EQ(saturating_add(kMax - 1, 1), kMax);
  EXPECT_EQ(saturating_add(kMax, kMax), kMax);
  EXPECT_EQ(saturating_mul(1u << 20, 1u << 20), uint64_t(1) << 40);
  EXPECT_EQ(saturating_mul(uint64_t(1) << 51, 100000), kMax);  // the most samples x frames
  EXPECT_EQ(saturating_mul(0, kMax), 0u);
}

}  // namespace
}  // namespace tessera
