// Denoising an image file: the one path from an EXR with the denoising layers to a
// denoised EXR, taken by `tessera denoise`, by `tessera render --denoise` (which writes the
// noisy EXR first) and by the coordinator for a --denoise job's final image. The denoiser
// reads only the file's float channels, so the same noisy file gives the same bits
// wherever it was rendered (the farm's EXR already equals tessera render's).
#pragma once

#include <string>
#include <vector>

#include "core/denoise/denoiser.h"

namespace tessera {

// The EXR channels the denoiser needs besides R, G, B (--aov denoising writes them).
extern const std::vector<std::string> kDenoiseChannels;
// The noisy image, kept in a denoised file.
inline constexpr const char* kNoisyChannels[3] = {"noisy.R", "noisy.G", "noisy.B"};

struct DenoiseReport {
  int width = 0, height = 0;
  double seconds = 0;  // the denoiser's own time (reading and writing apart)
};

// Reads `in`, denoises it and writes `out` (may be `in`; written to a temporary file and
// renamed into place): every channel and string attribute of `in`, with R, G, B denoised
// and the noisy image as noisy.R/G/B, ZIP-compressed, and the attribute tessera/denoiser.
// Throws std::runtime_error naming the file: unreadable, or without the layers needed.
// Works in bands of rows (options.band_rows; about a million pixels each), each read with
// kDenoiseReach rows more on both sides and written as it is done: memory is a band's,
// not the image's (an 8K frame's final costs a coordinator about 400 MB, not 5 GB), and
// the bits are the whole image's.
DenoiseReport denoise_exr(const std::string& in, const std::string& out, const DenoiseOptions& options = {});

}  // namespace tessera
