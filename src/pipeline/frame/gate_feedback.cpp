#include "pipeline/frame/gate_feedback.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace loopgate {

void GateFeedback::submitted(std::size_t query_frame) {
  std::lock_guard lock(mutex_);
  ++pending_[query_frame];
}

void GateFeedback::done(std::size_t query_frame, const FeedbackLoop* verified) {
  {
    std::lock_guard lock(mutex_);
    const auto it = pending_.find(query_frame);
    if (it == pending_.end()) {
      throw std::logic_error(
          fmt::format("gate feedback: loop of frame {} done, never submitted", query_frame));
    }
    if (--it->second == 0) pending_.erase(it);
    if (verified) {
      const auto at = std::upper_bound(verified_.begin(), verified_.end(), verified->query,
                                       [](std::size_t q, const FeedbackLoop& l) { return q < l.query; });
      verified_.insert(at, *verified);
    }
  }
  changed_.notify_all();
}

void GateFeedback::final_through(std::size_t frame) {
  std::lock_guard lock(mutex_);
  if (!final_through_ || frame > *final_through_) final_through_ = frame;
}

std::optional<FeedbackLoop> GateFeedback::anchor_through(
    std::size_t frame, const std::function<bool(const FeedbackLoop&)>& usable) {
  std::unique_lock lock(mutex_);
  if (!final_through_ || *final_through_ < frame) {
    throw std::logic_error(fmt::format(
        "gate feedback: the gate needs the loops of frames <= {}, and the detections are final only through "
        "{}: the lag L = {} frames is shorter than run.max_in_flight + the method's verdict delay",
        frame, final_through_ ? fmt::format("frame {}", *final_through_) : std::string("no frame"),
        lag_frames_));
  }
  const auto all_done = [&] { return pending_.empty() || pending_.begin()->first > frame; };
  if (!all_done()) {
    const auto start = std::chrono::steady_clock::now();
    changed_.wait(lock, all_done);
    wait_ms_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    ++frames_waited_;
  }
  auto it = std::upper_bound(verified_.begin(), verified_.end(), frame,
                             [](std::size_t q, const FeedbackLoop& l) { return q < l.query; });
  while (it != verified_.begin()) {
    --it;
    if (usable(*it)) return *it;
  }
  return std::nullopt;
}

double GateFeedback::wait_ms() const {
  std::lock_guard lock(mutex_);
  return wait_ms_;
}

std::size_t GateFeedback::frames_waited() const {
  std::lock_guard lock(mutex_);
  return frames_waited_;
}

}  // namespace loopgate
