// The matching end of a DIRD method (full or gated, raw or standardised): the streaming sequence matcher
// (DP + NMS, docs/detection.md § The paper's matcher), its loop closures to loops.csv, and the frames'
// detection rows once the matcher has finalised them. Rows go in through push() in sequence order (the serial
// match node); the sink reads detection(seq) in sequence order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "pipeline/methods/detection_method.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

class LoopMatching {
 public:
  explicit LoopMatching(const MethodContext& context);

  SequenceMatcher& matcher() { return matcher_; }
  // Frames after which the matcher's verdict of a row pushed is final (its NMS delay).
  std::int64_t emission_delay() const { return matcher_.emission_delay(); }
  // The row S(., seq) of frame `seq` (the next one) to the matcher.
  void push(std::size_t seq, const std::vector<SimilarityEntry>& row);
  // End of stream: the matcher's last rows.
  void flush();
  // Loop closures to loops.csv; finalised frame statuses to the queue the sink reads.
  void handle(const MatchOutput& output);

  // The detection row of `seq` when the matcher has finalised it; `described`: the frame had a
  // descriptor; `outside_areas` (gated): its row had no cell.
  std::optional<FrameVerdict> detection(std::size_t seq, bool described, bool outside_areas);

  // The query frame of the first loop closure, if any.
  std::optional<std::int64_t> first_loop_seq() const { return first_loop_seq_; }
  // summary.json: detection.nms_delay_frames.
  nlohmann::json summary() const;

 private:
  const MethodContext context_;  // references to the run's objects (a copy: the struct is a temporary)
  SequenceMatcher matcher_;
  std::optional<std::int64_t> first_loop_seq_;
  std::mutex finished_mutex_;
  std::deque<FrameMatchStatus> finished_;
};

}  // namespace loopgate
