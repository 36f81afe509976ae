// The tessera command-line client.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "client/denoise_command.h"
#include "client/farm_commands.h"
#include "client/render_command.h"
#include "core/io/files.h"
#include "core/io/interrupt_cleanup.h"
#include "core/scene/scene_error.h"
#include "core/util/cli.h"

int main(int argc, char** argv) {
  tessera::install_interrupt_cleanup();  // Ctrl-C leaves no half-written download or output
  tessera::use_unique_temporaries();     // two commands writing one output keep apart
  CLI::App app{"Tessera: a path-tracing render farm"};
  app.require_subcommand(1);
  std::string cmdline = "tessera";
  for (int i = 1; i < argc; ++i) cmdline += std::string(" ") + argv[i];
  std::vector<std::function<int()>> commands{tessera::add_render_command(app, cmdline)};
  for (auto& c : tessera::add_farm_commands(app)) commands.push_back(std::move(c));
  commands.push_back(tessera::add_denoise_command(app));
  tessera::add_version_flag(app, "tessera");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return tessera::cli_exit(app, e);
  }
  try {
    for (auto& run : commands)
      if (int rc = run(); rc >= 0) return rc;
    return 1;
  } catch (const CLI::ParseError& e) {  // a flag's value found wrong once read (a --frames range, say)
    return tessera::cli_exit(app, e);
  } catch (const tessera::SceneError& e) {
    std::fprintf(stderr, "tessera: error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera: error: %s\n", e.what());
    return 1;
  }
}
