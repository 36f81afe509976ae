// What every binary's command line shares, as the tools operators know: --version (the
// commit it was built from) and exit code 2 for a usage error (CLI11's own codes are 100
// and up), 0 for --help and --version. Header-only: only the mains include it (CLI11).
#pragma once

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <string>

#include "core/util/version.h"

namespace tessera {

inline void add_version_flag(CLI::App& app, const std::string& program) {
  app.set_version_flag("--version", program + " " + version());
}

// An option's spelling before a rename (one spelling per option across the binaries),
// still accepted so that scripts and unit files written earlier keep working: listed apart
// in --help (CLI11 drops a hidden option's name from its errors), bound to the same value,
// and saying on stderr which name to use now. The caller repeats the new option's checks on
// the returned option.
template <typename T>
CLI::Option* add_old_spelling(CLI::App& app, const std::string& old_name, const std::string& new_name, T& value) {
  return app.add_option(old_name, value, "now " + new_name)
      ->group("Old spellings, still accepted")
      ->each([old_name, new_name](const std::string&) {
        std::fprintf(stderr, "%s is now spelled %s; the old spelling will go\n", old_name.c_str(), new_name.c_str());
      });
}

// CLI::Range for a floating-point option that refuses NaN too: CLI11's Range lets "nan"
// through (every comparison with NaN is false), and a NaN bound or interval turned into
// an integer is undefined behaviour. Same message as CLI11's Range.
inline CLI::Validator finite_range(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        double v = 0;
        try {
          size_t used = 0;
          v = std::stod(text, &used);
          if (used != text.size()) return "Value " + text + " is not a number";
        } catch (const std::exception&) {
          return "Value " + text + " is not a number";
        }
        if (!(v >= lo && v <= hi))
          return "Value " + text + " not in range " + std::to_string(lo) + " to " + std::to_string(hi);
        return "";
      },
      "FLOAT in [" + std::to_string(lo) + " - " + std::to_string(hi) + "]");
}

// Prints CLI11's message for a parse error (usage to stdout for --help) and returns the
// exit code.
inline int cli_exit(CLI::App& app, const CLI::Error& e) { return app.exit(e) == 0 ? 0 : 2; }

}  // namespace tessera
