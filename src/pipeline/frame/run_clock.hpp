// The run's clock and the replay of the source: `rate: max` releases a frame as soon as fewer than K
// (run.max_in_flight) frames are in the graph (back-pressure, no drops); `rate: R` releases frame i at
// start + (t_i - t_first) / R on a steady clock and drops it (counted, before it gets a sequence number)
// when K frames are in flight. Waits poll the stop condition every 20 ms.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>

#include "pipeline/pipeline_config.hpp"

namespace loopgate {

class Dataset;

class RunClock {
 public:
  using Clock = std::chrono::steady_clock;
  void restart() { start_ = Clock::now(); }
  std::int64_t now_ns() const {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - start_).count();
  }

 private:
  Clock::time_point start_ = Clock::now();
};

class ReplayClock {
 public:
  ReplayClock(const RunConfig& run, const Dataset& dataset, std::size_t first_frame, const RunClock& clock);

  struct Release {
    bool go = false;               // false: the frame was dropped (rate mode)
    std::int64_t deadline_ns = 0;  // rate mode: when it should leave the sink; 0: none
  };
  // Waits until `frame` may be released; nullopt when `stop()` became true while waiting. Counts every
  // frame presented and every drop.
  std::optional<Release> wait_for(std::size_t frame, const std::function<bool()>& stop);
  void frame_entered();  // the released frame is in the graph
  void frame_left();     // the sink is done with a frame
  void wake();           // a failure: wake the producer

  std::size_t frames_in() const { return frames_in_; }
  std::size_t frames_dropped() const { return frames_dropped_; }

 private:
  const RunConfig& run_;
  const Dataset& dataset_;
  const RunClock& clock_;
  std::optional<double> rate_;
  Timestamp t_first_ns_ = 0;
  std::int64_t start_ns_ = 0;
  bool started_ = false;
  std::size_t frames_in_ = 0, frames_dropped_ = 0;
  std::mutex mutex_;
  std::condition_variable cv_;
  int in_flight_ = 0;
};

}  // namespace loopgate
