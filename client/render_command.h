// `tessera render`: the single-process path.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <string>

namespace tessera {

// Adds the render subcommand to `app`; returns a function that runs it after parsing.
// `command_line` is recorded in the image metadata.
std::function<int()> add_render_command(CLI::App& app, const std::string& command_line);

}  // namespace tessera
