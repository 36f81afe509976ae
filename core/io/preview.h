// A small sRGB PNG of an EXR image, for the live page: read a band of rows at a time and
// box-filtered down to at most `max_width` pixels wide (a whole factor, so every preview
// pixel averages the same number of image pixels), so an 8K image costs a few rows of
// floats, not the image.
#pragma once

#include <map>
#include <string>

namespace tessera {

// Throws std::runtime_error naming the path.
std::string preview_png(const std::string& exr_path, int max_width = 1280);
// The EXR's R, G, B as a full-size PNG at the exposure it records, as encode_png of the
// image read whole gives it (the same bytes), reading the three channels only, a row at a
// time: a farm download's PNG (the EXR's other layers, AOVs or a noisy copy, never loaded).
std::string full_png(const std::string& exr_path);
// The same written to `png_path` as it is encoded (atomically: the old file or the whole
// new one), so that the PNG is never whole in memory either.
void write_full_png(const std::string& exr_path, const std::string& png_path);

// Whether the EXR at `exr_path` decodes whole: every block read (a truncated file, a
// damaged block or a checksum that fails stops it), a band of rows at a time. `why` gets
// OpenEXR's reason otherwise.
bool exr_intact(const std::string& exr_path, std::string* why = nullptr);

// The string attributes of the EXR at `exr_path` by name, from its header alone; none
// where the file is missing or its header does not read.
std::map<std::string, std::string> exr_string_attributes(const std::string& exr_path);

}  // namespace tessera
