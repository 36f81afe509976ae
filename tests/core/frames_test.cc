// Frame ranges (--frames) and per-frame paths: what a user types, and what is refused.
#include "core/render/frames.h"

#include <gtest/gtest.h>

#include "core/render/settings.h"

namespace tessera {
namespace {

TEST(Frames, RangesStepsListsAndMixes) {
  EXPECT_EQ(parse_frames("1-5"), (std::vector<int>{1, 2, 3, 4, 5}));
  EXPECT_EQ(parse_frames("1-9x3"), (std::vector<int>{1, 4, 7}));
  EXPECT_EQ(parse_frames("1,5,9"), (std::vector<int>{1, 5, 9}));
  EXPECT_EQ(parse_frames("7"), (std::vector<int>{7}));
  EXPECT_EQ(parse_frames("10-12,1,20-30x10"), (std::vector<int>{10, 11, 12, 1, 20, 30}));
  EXPECT_EQ(parse_frames("-2-1"), (std::vector<int>{-2, -1, 0, 1}));
  EXPECT_EQ(parse_frames("-5--4"), (std::vector<int>{-5, -4}));
  EXPECT_EQ(parse_frames("1-240").size(), 240u);
  EXPECT_EQ(parse_frames("1-240x2").size(), 120u);
}

TEST(Frames, BadInputIsRefusedNamingThePart) {
  auto refused = [](const std::string& spec, const std::string& why) {
    try {
      parse_frames(spec);
      ADD_FAILURE() << "'" << spec << "' accepted";
    } catch (const SettingsError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.rfind("--frames: ", 0), 0u) << what;
      EXPECT_NE(what.find(why), std::string::npos) << spec << ": " << what;
    }
  };
  refused("", "no frames given");
  refused("1,,2", "an empty part");
  refused("1,", "an empty part");
  refused("5-1", "'5-1': the range runs backwards");
  refused("1-10x0", "'1-10x0': the step after 'x' must be at least 1");
  refused("1-10x-2", "must be at least 1");
  refused("3x2", "a step needs a range");
  refused("a-5", "'a' is not a frame number");
  refused("1-5b", "'5b' is not a frame number");
  refused("1-", "'' is not a frame number");
  refused("1.5", "is not a frame number");
  refused("1-3,2", "frame 2 is given twice");
  refused("0-2000000", "within -1000000..1000000");
  refused("99999999999999999999", "is not a frame number");
  refused("-1000000-1000000", "more than 100000 frames");
}

TEST(Frames, PathsFromPatterns) {
  EXPECT_EQ(frame_path("out/shot.####.exr", 7), "out/shot.0007.exr");
  EXPECT_EQ(frame_path("shot.#.png", 123), "shot.123.png");
  EXPECT_EQ(frame_path("a#b.##.exr", 5), "a#b.05.exr");  // the last run
  EXPECT_EQ(frame_path("shot.###.exr", -7), "shot.-07.exr");
  EXPECT_EQ(frame_path("still.exr", 3), "still.exr");
  // Found by audit: a run longer than 31 was cut to 31 zeros, the number lost, and every
  // frame of a sequence wrote the same file.
  EXPECT_EQ(frame_path("shot." + std::string(40, '#') + ".png", 12), "shot." + std::string(38, '0') + "12.png");
  EXPECT_EQ(frame_path("s." + std::string(40, '#'), -3), "s.-" + std::string(38, '0') + "3");
}

}  // namespace
}  // namespace tessera
