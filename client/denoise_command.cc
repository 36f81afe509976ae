#include "client/denoise_command.h"

#include <cstdio>
#include <memory>

#include "core/denoise/denoise_exr.h"

namespace tessera {

std::function<int()> add_denoise_command(CLI::App& app) {
  struct Args {
    std::string in, out;
    int threads = 0;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(
      "denoise",
      "Denoise an EXR rendered with --denoise or --aov denoising (it needs the even/odd half-buffers, albedo, normal "
      "and depth layers); the noisy image is kept in OUT as noisy.R/G/B");
  cmd->add_option("IN", args->in, "The noisy EXR")->required()->check(CLI::ExistingFile);
  cmd->add_option("OUT", args->out, "Where the denoised EXR goes (may be IN)")->required();
  cmd->add_option("-t,--threads", args->threads, "Threads (0 = all cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1024));
  return [args, cmd] {
    if (!cmd->parsed()) return -1;
    DenoiseOptions options;
    options.threads = args->threads;
    const DenoiseReport r = denoise_exr(args->in, args->out, options);
    std::printf("%s: %dx%d denoised in %.2f s -> %s\n", args->in.c_str(), r.width, r.height, r.seconds,
                args->out.c_str());
    return 0;
  };
}

}  // namespace tessera
