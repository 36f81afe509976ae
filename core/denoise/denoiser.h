// A feature-guided Monte Carlo denoiser after NFOR, "Nonlinearly Weighted First-order
// Regression for Denoising Monte Carlo Renderings" (Bitterli, Rousselle, Moon, Iglesias-
// Guitian, Adler, Mitchell, Jarosz, Novak; EGSR 2016), with the NL-means weights and dual-
// buffer variance of Rousselle, Manzi and Zwicker ("Adaptive rendering with non-local means
// filtering", SIGGRAPH Asia 2012; "Robust denoising using feature and color information",
// Pacific Graphics 2013). A pure function over image buffers: no neural network, no state,
// the same bits for any thread count (and for the 4- and 8-lane SIMD kernels).
//
// What it does:
//  1. Variance: a half-buffer's per-channel variance is (even - odd)^2 / 2, smoothed by a
//     7 x 7 box (Rousselle 2012's dual-buffer estimate; one sample of it is mostly noise).
//  2. Candidate filters (NFOR 5.2): each half-buffer, at each pixel p, is fitted over a
//     13 x 13 window by weighted least squares, colour(q) ~ a + b . (f(q) - f(p)), with
//     f = (albedo rgb, normal xyz, log depth); a is the filtered pixel. The weights are
//     NL-means weights (5 x 5 patches, variance-normalised distances) computed on the OTHER
//     half (cross-filtering: a half's noise does not pick its own weights), times loose
//     feature weights. A relative ridge on the slopes keeps degenerate windows (constant
//     features, background) solvable; Gaussian elimination with the intercept last gives a
//     without the slopes. Where the fit is negative though the weighted mean is not (a line
//     extrapolated past what the window holds, next to fireflies), the weighted mean is used.
//     Four candidates: NL-means bandwidth k = 0.5 and k = 1, each fitted over the whole
//     window and over its central 7 x 7 (the same sums, split: less bias where the features
//     explain little, as on mirrors, whose first hit says nothing of what they reflect).
//  3. Selection (NFOR 5.3): each candidate's MSE, estimated from the halves (the other half
//     as the reference, less the filtered halves' residual difference and the pixel's own
//     (even - odd)^2 / 2), and a fifth candidate, the noisy colour itself, whose MSE is
//     estimated as (even - odd)^2 / 4 on the same footing. Each relative to an estimate of
//     colour^2 that no candidate moves (even x odd) and smoothed; the candidate with the
//     least per pixel, as a 0/1 map a candidate, each map smoothed, blends them. Where no
//     filter beats the noise (detail no feature explains: reflections, refractions) the
//     pixel stays (nearly) as noisy as it came, rather than blurred.
//  4. Zero estimated variance keeps the pixel: where the smoothed variance is 0 in every
//     channel the output is the input colour, bit for bit (a noise-free image comes back
//     unchanged by construction, not by the filter's luck).
//
// Where it departs from NFOR, for speed (a 1080p frame in seconds on two cores; NFOR's
// reference implementation takes minutes on many) or because these buffers differ:
//  - a 13 x 13 window and 5 x 5 patches (NFOR: 19 x 19 and 7 x 7), and no collaborative
//    (overlapping-window) averaging of the fits: each pixel keeps its own window's intercept
//    (measured on rendered scenes: no better, and worse on diffuse ones);
//  - no slopes along screen x and y: measured, they help smooth diffuse shading only, for
//    two more unknowns (about 40% more time);
//  - features are used as given (NFOR prefilters them with NL-means on their own half-
//    buffers, which these buffers do not have), and depth enters as log depth;
//  - bandwidths k = 0.5 and 1, as NFOR's, but over two window sizes, and the noisy colour
//    as a candidate;
//  - the MSE estimates and selection maps are smoothed by 5 x 5 boxes where NFOR uses
//    NL-means guided by the colour, and the selection is per pixel, not per channel;
//  - no second pass (NFOR 5.4 filters once more, guided by the first pass's output): tried,
//    it did not help on rendered scenes;
//  - loose feature weights multiply the NL-means weights (as in Rousselle 2013), and the
//    NL-means distance is symmetric (2 min(var p, var q) is the variance cancelled), which
//    lets the weights at offset -o be read from those at o.
#pragma once

#include <cstdint>
#include <vector>

namespace tessera {

// Per-pixel planes, row-major, row 0 at the top; RGB planes hold 3 floats a pixel.
struct DenoiseBuffers {
  int width = 0, height = 0;
  int first_row = 0;             // the image row the buffers' row 0 is (a band of a larger image; for messages)
  int first_column = 0;          // and its column (an EXR's data window's left edge; for messages)
  std::vector<float> color;      // RGB: the mean of all of each pixel's samples (what the noisy image shows)
  std::vector<float> even, odd;  // RGB: means of each pixel's even- and odd-numbered samples (independent halves)
  std::vector<float> albedo;     // RGB: first-hit albedo in [0, 1], averaged over the pixel (0: background)
  std::vector<float> normal;     // 3 a pixel: world-space shading normal averaged over the pixel (0: background)
  std::vector<float> depth;      // 1 a pixel: camera distance averaged over the pixel's hits (1e10: nothing hit)
};

struct DenoiseOptions {
  int threads = 0;         // 0: std::thread::hardware_concurrency()
  bool wide_lanes = true;  // 8-lane AVX2 kernels where the CPU has them; the same bits as the 4-lane ones
  // denoise_exr: rows a band; 0: about a million pixels a band. Any band height gives the
  // same bits.
  int band_rows = 0;
};

// How far the output reaches: a pixel's result depends on the input within this many rows
// and columns of it (the variance's box 3, the NL-means patch 2, the regression window 6,
// the error box 2, the selection box 2). A band of rows denoised with this many rows more
// on each side (a halo) gives its rows the whole image's bits (denoise_exr).
constexpr int kDenoiseReach = 15;

// Colours past this magnitude are denoised scaled down by a power of two (exact) and the
// result scaled back: the filters' squares of colour differences overflow float near 2^64.
constexpr float kMaxDenoisedMagnitude = 0x1p40f;

// The denoised image, RGB, 3 floats a pixel. Throws std::invalid_argument naming the buffer
// that is missing, of the wrong size or holds a non-finite value, or the size if it is empty.
std::vector<float> denoise(const DenoiseBuffers& in, const DenoiseOptions& options = {});

// About the most memory denoise() holds for an image of this size, in bytes (its planes on
// the filters' padded grid and per pixel): denoise_exr sizes its bands by it.
uint64_t denoise_working_bytes(int width, int rows);

}  // namespace tessera
