// scripts/plot.py run from the commands that draw their results (compare, aggregate): one place that finds
// the script and runs it with the Debian interpreter that has matplotlib. A failure is a warning: the
// command's outputs stand without their pictures.
#pragma once

#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "io/share_dir.hpp"

namespace loopgate::app {

// --plot-script PATH, else $LOOPGATE_PLOT_SCRIPT, else scripts/plot.py of the installed tree
// (PREFIX/share/loopgate) or of the source tree (io::share_dir()).
inline std::filesystem::path find_plot_script(const std::string& option) {
  if (!option.empty()) return option;
  if (const char* env = std::getenv("LOOPGATE_PLOT_SCRIPT")) return env;
  return io::share_dir() / "scripts" / "plot.py";
}

inline std::string shell_quote(const std::string& text) {
  std::string out = "'";
  for (const char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Runs `/usr/bin/python3 SCRIPT ARGS...`; `who` names the command in the warnings. True when it succeeded.
inline bool run_plot_script(const std::string& script_option, const std::vector<std::string>& args,
                            const char* who) {
  const std::filesystem::path script = find_plot_script(script_option);
  if (!std::filesystem::exists(script)) {
    spdlog::warn("{}: no plots: {} not found (--plot-script PATH or LOOPGATE_PLOT_SCRIPT)", who,
                 script.string());
    return false;
  }
  std::string command = "/usr/bin/python3 " + shell_quote(script.string());
  for (const std::string& arg : args) command += " " + shell_quote(arg);
  std::fflush(stdout);  // the command's table before the plotter's own lines
  const int status = std::system(command.c_str());
  if (status != 0) spdlog::warn("{}: plotting failed (exit status {}): {}", who, status, command);
  return status == 0;
}

}  // namespace loopgate::app
