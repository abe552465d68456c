#include "app/stop_signals.hpp"

#include "core/stop_request.hpp"

namespace loopgate::app {

namespace {

constexpr int kSignals[3] = {SIGINT, SIGTERM, SIGHUP};
std::atomic<int> g_received{0};

extern "C" void on_stop_signal(int signal_number) {
  stop_request::record(signal_number);
  // The third signal of any of the three ends the process with the default action.
  if (g_received.fetch_add(1) + 1 >= 2) {
    struct sigaction dfl {};
    dfl.sa_handler = SIG_DFL;
    sigemptyset(&dfl.sa_mask);
    for (const int s : kSignals) sigaction(s, &dfl, nullptr);
  }
}

}  // namespace

StopSignals::StopSignals() {
  stop_request::reset();
  g_received.store(0);
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;  // a write interrupted by the signal goes on (no spurious write error)
  for (int k = 0; k < 3; ++k) sigaction(kSignals[k], &action, &previous_[k]);
}

StopSignals::~StopSignals() {
  for (int k = 0; k < 3; ++k) sigaction(kSignals[k], &previous_[k], nullptr);
}

const std::atomic<bool>* StopSignals::flag() const {
  return &stop_request::stop_flag();
}

bool StopSignals::stopped() const {
  return stop_request::stop();
}

int StopSignals::exit_code() const {
  return stop_request::exit_status();
}

std::string StopSignals::signal_name() const {
  return stop_request::signal_name(stop_request::signal_number());
}

}  // namespace loopgate::app
