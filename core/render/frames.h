// Frame ranges and per-frame output paths, for sequences (--frames, -f out.####.exr).
#pragma once

#include <string>
#include <vector>

namespace tessera {

// At most this many frames in one range: far beyond any sequence, small enough to list.
constexpr size_t kMaxFrames = 100000;

// "1-240", "1-240x2" (every second frame), "1,5,9", or a comma-separated mix of them
// ("1-10,20,30-40x5"), in the order given. Frames are within +-RenderSettings::kMaxFrame.
// Throws SettingsError("--frames", ...) naming the part that is wrong: empty parts, a
// range that runs backwards, a step below 1, a frame given twice, too many frames.
std::vector<int> parse_frames(const std::string& spec);

// `pattern` with its last run of '#' replaced by the frame number, zero-padded to the
// run's length ("shot.####.exr", 7 -> "shot.0007.exr"; -7 -> "shot.-007.exr"); a
// pattern without '#' is returned as it is.
std::string frame_path(const std::string& pattern, int frame);

}  // namespace tessera
