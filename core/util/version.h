// The build's version: the commit it was built from (`git describe`, with "-dirty" when the
// tree had uncommitted changes, "unknown" outside a git checkout). Every binary's --version
// prints it (core/util/cli.h).
#pragma once

namespace tessera {

const char* version();

}  // namespace tessera
