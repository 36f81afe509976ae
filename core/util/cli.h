// What every binary's command line shares, as the tools operators know: --version (the
// commit it was built from) and exit code 2 for a usage error (CLI11's own codes are 100
// and up), 0 for --help and --version. Header-only: only the mains include it (CLI11).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "core/util/version.h"

namespace tessera {

inline void add_version_flag(CLI::App& app, const std::string& program) {
  app.set_version_flag("--version", program + " " + version());
}

// Prints CLI11's message for a parse error (usage to stdout for --help) and returns the
// exit code.
inline int cli_exit(CLI::App& app, const CLI::Error& e) { return app.exit(e) == 0 ? 0 : 2; }

}  // namespace tessera
