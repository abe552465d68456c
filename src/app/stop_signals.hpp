// SIGINT, SIGTERM and SIGHUP for a command that writes outputs (run, compare, simulate): while a StopSignals
// lives, each is recorded in core/stop_request.hpp instead of ending the process. The first one asks the
// command to stop (a run drains and writes everything, exit 128 + signal: 130, 143, 129); a second one asks
// long loops to abort (what is written stays); a third ends the process at once (the default action). The
// previous handlers are restored by the destructor. SIGXFSZ (a file-size limit reached) is ignored by main()
// so that it becomes a write error, reported like a full disk.
#pragma once

#include <atomic>
#include <csignal>
#include <string>

namespace loopgate::app {

class StopSignals {
 public:
  StopSignals();  // also clears earlier requests
  ~StopSignals();
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  // The flag the pipeline polls (set by the first signal).
  const std::atomic<bool>* flag() const;
  bool stopped() const;
  // 128 + the first signal (130 SIGINT, 143 SIGTERM, 129 SIGHUP); 0 when none arrived.
  int exit_code() const;
  std::string signal_name() const;  // "SIGTERM"

 private:
  struct sigaction previous_[3];
};

}  // namespace loopgate::app
