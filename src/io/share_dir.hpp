// Where loopgate's shipped files are (the simulator presets configs/sim, the example configs, the plot
// script scripts/plot.py): beside the running binary when it is installed, else the source tree it was built
// from.
#pragma once

#include <filesystem>

namespace loopgate::io {

// PREFIX/share/loopgate when the running binary is PREFIX/bin/loopgate and that folder holds configs/sim
// (`cmake --install`, the Debian package, or a copy of the installed tree moved elsewhere); else the source
// folder compiled into the binary (a build tree). Both hold configs/ and scripts/plot.py at the same paths.
std::filesystem::path share_dir();

// The installed folder share_dir() looks for beside `binary` (BIN/../share/loopgate); exposed for tests.
std::filesystem::path installed_share_dir(const std::filesystem::path& binary);

}  // namespace loopgate::io
