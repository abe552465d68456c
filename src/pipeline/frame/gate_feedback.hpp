// The channel of gate.feedback (docs/gating.md § Gate feedback): the loop closer's verified
// loops and the sink's "detections final through frame w" to the pose gate, which re-anchors frame i through
// the latest verified loop whose query frame is <= frame(i - L) (stages/gate/reanchor.hpp).
//
// The rule that makes the gate's input independent of timing: the gate of frame i uses exactly the verified
// loops of the query frames <= frame(i - L), L = run.max_in_flight (K) + the method's verdict delay D (frame
// s's verdict and every loop whose query is s are final once match() of s + D has run). It waits until the
// closer has verified every one of them, never takes "whatever is ready now".
//
// Why the wait ends (also with --threads 1, where the waiting gate holds the only TBB worker): frame i enters
// the graph only after frame i - K left the sink (the limiter), whose match() ran before; so every loop with
// a query frame <= frame(i - K - D) = frame(i - L) was already submitted to the closer, and the sink of frame
// i - K published final_through >= frame(i - L) (checked: a violation is a logic error, never a wait). The
// closer verifies on its own std::thread, outside the TBB arena, and needs nothing from the graph (images are
// read through the dataset), so every submitted loop is verified in finite time. The verification itself
// does not depend on timing (the loop closer's order of submission is the match node's), and the pose-graph
// solves (time-bounded) are not used.
//
// Threading: submitted() from the match node (LoopsWriter's listener), done() from the closer's worker,
// final_through() from the sink, anchor_through() from the gate node; all under one mutex.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

namespace loopgate {

// A verified loop as the gate uses it (dataset frame indices).
struct FeedbackLoop {
  std::size_t query = 0;
  std::size_t reference = 0;
  Eigen::Isometry3d T_r_q = Eigen::Isometry3d::Identity();  // body q in body r
  Eigen::Matrix3d P_loop_r_m2 = Eigen::Matrix3d::Zero();    // position covariance of T_r_q, r's body frame
};

class GateFeedback {
 public:
  // The lag L in frames (sequence numbers), set once before the run starts.
  void set_lag(std::size_t lag_frames) { lag_frames_ = lag_frames; }
  std::size_t lag_frames() const { return lag_frames_; }

  // A loop with this query frame was submitted to the closer (call before the closer can finish it).
  void submitted(std::size_t query_frame);
  // The closer finished a loop of this query frame: `verified` when it was verified, else nullptr (rejected
  // or skipped).
  void done(std::size_t query_frame, const FeedbackLoop* verified);
  // The detection of dataset frame `frame` is final: every loop whose query frame is <= frame was submitted.
  void final_through(std::size_t frame);

  // Blocks until every loop submitted with a query frame <= `frame` is done; then the latest verified one
  // (largest query frame, then the last submitted) for which `usable` is true, going back from the latest.
  // Throws std::logic_error when final_through() has not reached `frame` (the lag rule was broken: waiting
  // could deadlock).
  std::optional<FeedbackLoop> anchor_through(std::size_t frame,
                                             const std::function<bool(const FeedbackLoop&)>& usable);

  // Time the gate waited for the closer (wall time, for the summary; not part of any output's content).
  double wait_ms() const;
  std::size_t frames_waited() const;

 private:
  std::size_t lag_frames_ = 0;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::map<std::size_t, int> pending_;  // query frame -> loops submitted, not done
  std::vector<FeedbackLoop> verified_;  // sorted by query frame; equal queries in submission order
  std::optional<std::size_t> final_through_;
  double wait_ms_ = 0;
  std::size_t frames_waited_ = 0;
};

}  // namespace loopgate
