#include "core/render/frames.h"

#include <cstdio>
#include <set>

#include "core/render/settings.h"

namespace tessera {

namespace {

[[noreturn]] void bad(const std::string& part, const std::string& why) {
  throw SettingsError("--frames", "'" + part + "': " + why);
}

// A whole signed integer within the frame range, or an error naming `part`.
int frame_number(const std::string& text, const std::string& part) {
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(text, &used);
  } catch (const std::exception&) {
    bad(part, "'" + text + "' is not a frame number");
  }
  if (used != text.size()) bad(part, "'" + text + "' is not a frame number");
  if (v < -RenderSettings::kMaxFrame || v > RenderSettings::kMaxFrame)
    bad(part, "frames must be within -1000000..1000000");
  return int(v);
}

}  // namespace

std::vector<int> parse_frames(const std::string& spec) {
  if (spec.empty()) bad(spec, "no frames given (e.g. 1-240, 1-240x2, 1,5,9)");
  std::vector<int> frames;
  std::set<int> seen;
  size_t begin = 0;
  while (true) {
    const size_t comma = spec.find(',', begin);
    const std::string part = spec.substr(begin, comma == std::string::npos ? std::string::npos : comma - begin);
    if (part.empty()) bad(spec, "an empty part between commas");
    std::string range = part;
    int step = 1;
    if (const size_t x = part.find('x'); x != std::string::npos) {
      step = frame_number(part.substr(x + 1), part);
      if (step < 1) bad(part, "the step after 'x' must be at least 1");
      range = part.substr(0, x);
    }
    // A '-' after the first character separates the ends ("-5--1" runs from -5 to -1).
    const size_t dash = range.find('-', 1);
    const int first = frame_number(range.substr(0, dash), part);
    const int last = dash == std::string::npos ? first : frame_number(range.substr(dash + 1), part);
    if (last < first) bad(part, "the range runs backwards");
    if (dash == std::string::npos && step != 1) bad(part, "a step needs a range (e.g. 1-240x2)");
    if ((int64_t(last) - first) / step + 1 + frames.size() > kMaxFrames)
      bad(part, "more than " + std::to_string(kMaxFrames) + " frames");
    for (int64_t f = first; f <= last; f += step) {
      if (!seen.insert(int(f)).second) bad(part, "frame " + std::to_string(f) + " is given twice");
      frames.push_back(int(f));
    }
    if (comma == std::string::npos) break;
    begin = comma + 1;
  }
  return frames;
}

std::string frame_path(const std::string& pattern, int frame) {
  const size_t end = pattern.find_last_of('#');
  if (end == std::string::npos) return pattern;
  size_t start = end;
  while (start > 0 && pattern[start - 1] == '#') --start;
  const int width = int(end - start + 1);
  // (Any run: a 32-byte buffer cut a run of 40 to 31 zeros and every frame wrote one file.)
  std::string number = std::to_string(frame < 0 ? -int64_t(frame) : int64_t(frame));
  if (int(number.size()) < width - (frame < 0)) number.insert(0, size_t(width - (frame < 0)) - number.size(), '0');
  if (frame < 0) number.insert(0, 1, '-');
  return pattern.substr(0, start) + number + pattern.substr(end + 1);
}

}  // namespace tessera
