#include "pipeline/frame/run_clock.hpp"

#include <algorithm>
#include <thread>

#include "io/dataset.hpp"

namespace loopgate {

namespace {
constexpr auto kPollPeriod = std::chrono::milliseconds(20);

// dt / rate in ns, clamped to a century: run.rate is bounded, but a dataset may span any time, and a cast
// of a double beyond int64 would be undefined behaviour.
std::int64_t scaled_ns(std::int64_t dt_ns, double rate) {
  constexpr double kMaxNs = 100.0 * 365.25 * 86400.0 * 1e9;
  const double scaled = static_cast<double>(dt_ns) / rate;
  return static_cast<std::int64_t>(std::clamp(scaled, -kMaxNs, kMaxNs));
}
}  // namespace

ReplayClock::ReplayClock(const RunConfig& run, const Dataset& dataset, std::size_t first_frame,
                         const RunClock& clock)
    : run_(run),
      dataset_(dataset),
      clock_(clock),
      rate_(run.rate_factor()),
      t_first_ns_(dataset.frame_t_ns(first_frame)) {}

std::optional<ReplayClock::Release> ReplayClock::wait_for(std::size_t frame,
                                                          const std::function<bool()>& stop) {
  if (!started_) {
    started_ = true;
    start_ns_ = clock_.now_ns();
  }
  if (stop()) return std::nullopt;
  const Timestamp t_ns = dataset_.frame_t_ns(frame);
  Release release;
  if (!rate_) {
    std::unique_lock lock(mutex_);
    while (in_flight_ >= run_.max_in_flight && !stop()) cv_.wait_for(lock, kPollPeriod);
    if (stop()) return std::nullopt;
    ++frames_in_;
    release.go = true;
    return release;
  }
  // Release on the replay clock; sleep in short slices so that a stop request is seen quickly.
  const std::int64_t release_ns = start_ns_ + scaled_ns(t_ns - t_first_ns_, *rate_);
  while (!stop() && clock_.now_ns() < release_ns) {
    std::this_thread::sleep_for(std::min<std::chrono::nanoseconds>(
        std::chrono::nanoseconds(release_ns - clock_.now_ns()), kPollPeriod));
  }
  if (stop()) return std::nullopt;
  ++frames_in_;
  {
    std::lock_guard lock(mutex_);
    if (in_flight_ >= run_.max_in_flight) {
      ++frames_dropped_;
      return release;  // dropped before it gets a sequence number
    }
  }
  double budget_ns = run_.deadline_ms * 1e6;
  if (budget_ns <= 0) {
    const Timestamp next_t_ns = frame + 1 < dataset_.frame_count() ? dataset_.frame_t_ns(frame + 1) : t_ns;
    const Timestamp prev_t_ns = frame > 0 ? dataset_.frame_t_ns(frame - 1) : t_ns;
    const Timestamp period_ns = next_t_ns > t_ns ? next_t_ns - t_ns : t_ns - prev_t_ns;
    budget_ns = static_cast<double>(scaled_ns(period_ns, *rate_));
  }
  release.go = true;
  release.deadline_ns = clock_.now_ns() + static_cast<std::int64_t>(budget_ns);
  return release;
}

void ReplayClock::frame_entered() {
  std::lock_guard lock(mutex_);
  ++in_flight_;
}

void ReplayClock::frame_left() {
  {
    std::lock_guard lock(mutex_);
    --in_flight_;
  }
  cv_.notify_all();
}

void ReplayClock::wake() {
  cv_.notify_all();
}

}  // namespace loopgate
