#include "core/stop_request.hpp"

#include <csignal>

namespace loopgate::stop_request {

namespace {
std::atomic<bool> g_stop{false};
std::atomic<bool> g_abort{false};
std::atomic<int> g_signal{0};
static_assert(std::atomic<bool>::is_always_lock_free && std::atomic<int>::is_always_lock_free,
              "signal handlers need lock-free flags");
}  // namespace

void record(int signal_number) noexcept {
  int expected = 0;
  g_signal.compare_exchange_strong(expected, signal_number);
  if (g_stop.exchange(true)) g_abort.store(true);
}

const std::atomic<bool>& stop_flag() noexcept {
  return g_stop;
}
bool stop() noexcept {
  return g_stop.load();
}
bool abort() noexcept {
  return g_abort.load();
}
int signal_number() noexcept {
  return g_signal.load();
}
int exit_status() noexcept {
  const int s = g_signal.load();
  return s > 0 ? 128 + s : 0;
}

std::string signal_name(int signal_number) {
  switch (signal_number) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    default: return "signal " + std::to_string(signal_number);
  }
}

void reset() noexcept {
  g_stop.store(false);
  g_abort.store(false);
  g_signal.store(0);
}

void check_abort(const char* what) {
  if (g_abort.load()) {
    throw Interrupted(std::string(what) + ": aborted by a second " + signal_name(g_signal.load()));
  }
}

}  // namespace loopgate::stop_request
