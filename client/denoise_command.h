// `tessera denoise IN.exr OUT.exr`: denoises an image rendered with the denoising layers
// (--denoise or --aov denoising), here or on a farm.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace tessera {

// Adds the denoise subcommand to `app`; returns a function that runs it after parsing.
std::function<int()> add_denoise_command(CLI::App& app);

}  // namespace tessera
