#include "io/share_dir.hpp"

#include <system_error>

namespace loopgate::io {

std::filesystem::path installed_share_dir(const std::filesystem::path& binary) {
  return binary.parent_path().parent_path() / "share" / "loopgate";
}

std::filesystem::path share_dir() {
  std::error_code ec;
  // Linux: the running binary's own path, symbolic links resolved (a link in ~/bin still finds its tree).
  const std::filesystem::path binary = std::filesystem::canonical("/proc/self/exe", ec);
  if (!ec) {
    const std::filesystem::path installed = installed_share_dir(binary);
    if (std::filesystem::is_directory(installed / "configs" / "sim", ec)) return installed;
  }
  return LOOPGATE_SOURCE_DIR;
}

}  // namespace loopgate::io
