// `tessera submit | status | jobs | watch | fetch | cancel`: the farm's client side.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <vector>

namespace tessera {

// Adds the farm subcommands to `app`; each returned function runs its command if it was
// the one parsed (returning -1 otherwise).
std::vector<std::function<int()>> add_farm_commands(CLI::App& app);

}  // namespace tessera
