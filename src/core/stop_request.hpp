// Process-wide stop requests. The app's signal handlers (SIGINT, SIGTERM, SIGHUP; src/app/stop_signals.hpp)
// record them; long-running work reads them.
//  - The first signal asks to stop: a run takes no new input, finishes the frames in flight and writes every
//    output (the pipeline polls stop_flag()).
//  - A second signal asks to abort: long loops (SeqSLAM's difference matrix and search, the two-sequence
//    passes, dird-seqslam's two-sequence search among them) throw Interrupted at their next check_abort();
//    whatever is already written stays written. The per-frame work of the DIRD and contrast matchers is
//    bounded by the parameter bounds instead (docs/reliability.md, Limits).
// Everything here is lock-free, so a signal handler may call record().
#pragma once

#include <atomic>
#include <stdexcept>
#include <string>

namespace loopgate {

// Thrown by check_abort() once a second stop signal arrived.
class Interrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

namespace stop_request {

// Records a stop signal (async-signal-safe): the first one sets stop, a later one sets abort.
void record(int signal_number) noexcept;
// The flag the pipeline polls: set by the first signal.
const std::atomic<bool>& stop_flag() noexcept;
bool stop() noexcept;
bool abort() noexcept;
// The first signal received (0: none) and its conventional exit status 128 + signal (0: none).
int signal_number() noexcept;
int exit_status() noexcept;
// "SIGINT", "SIGTERM", "SIGHUP", or "signal N".
std::string signal_name(int signal_number);
// Clears every request (a command starting, or a test).
void reset() noexcept;
// Throws Interrupted("WHAT: aborted by a second SIGxxx") when an abort was requested.
void check_abort(const char* what);

}  // namespace stop_request
}  // namespace loopgate
