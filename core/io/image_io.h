// Writing films: OpenEXR (linear float RGB + spp + variance channels + metadata) and an
// sRGB PNG preview. Both write to a temporary file and rename it into place, so a reader
// never sees a half-written image.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/render/aov.h"
#include "core/render/film.h"
#include "core/scene/image_read.h"  // read_exr

namespace tessera {

using ImageMetadata = std::map<std::string, std::string>;

// Throws std::runtime_error naming the path on failure. `fast` trades file size for
// speed (no EXR compression, light PNG compression): for frequent progressive images.
// With `aovs` (not empty, the film's window), their channels too (settings' --aov bits).
// `frame`: the whole image the film's window is part of (-p), the EXR's display window;
// empty where the film is the whole image.
void write_exr(const std::string& path, const Film& film, const ImageMetadata& metadata, bool fast = false,
               const AovFilm* aovs = nullptr, uint32_t aov_bits = 0, const Rect& frame = {});
// `scale` multiplies the linear values before the sRGB transfer (an exposure: 2^EV).
void write_png(const std::string& path, const Film& film, bool fast = false, float scale = 1);
// The PNG file's bytes for linear RGB planes of w x h (row 0 at the top).
std::string encode_png(int w, int h, const float* r, const float* g, const float* b, bool fast = false,
                       float scale = 1);
// An EXR's R, G, B as a PNG at the exposure its metadata records (as every PNG made from
// an EXR: a farm download, a denoised render).
std::string encode_png(const ExrImage& image);
// Whether a path names an EXR (its extension).
bool is_exr_path(const std::string& path);
// Picks the format from the extension (.exr or .png); throws on anything else. A PNG takes
// its exposure from the metadata (exposure_scale), as every PNG made from the EXR does.
// An EXR is placed in `frame` as write_exr's; a PNG holds the film's pixels alone.
void write_image(const std::string& path, const Film& film, const ImageMetadata& metadata,
                 const AovFilm* aovs = nullptr, uint32_t aov_bits = 0, const Rect& frame = {});

// The metadata key that carries --exposure (the file's attribute: "tessera/exposure", as
// the writer prefixes every key and read_exr reads it), and the scale 2^EV it asks for (1
// without it, or for a value that is not a finite EV in -64..64). Either key is taken.
inline constexpr const char* kExposureAttribute = "exposure";
inline constexpr const char* kExposureFileAttribute = "tessera/exposure";
float exposure_scale(const ImageMetadata& metadata);
// An EV as the attribute holds it (exactly: the float's shortest round-trip text).
std::string exposure_text(float ev);

// sRGB transfer of a linear value, clamped to [0, 1], as an 8-bit code.
uint8_t srgb_byte(float linear);

}  // namespace tessera
