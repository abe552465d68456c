// The sequence matcher's verdict on one frame (FrameMatchStatus) in the outputs' words: outcome, label,
// best match and the reason text of frames.csv. Single- and two-sequence runs share it; what differs is
// said by the context.
#pragma once

#include <cstdint>

#include "core/types.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

struct MatchOutcomeContext {
  bool two_sequence =
      false;  // query vs reference (docs/detection.md § Two sequences): shorter reasons, no margin
  bool described = true;       // the frame had a descriptor when its status became final
  bool outside_areas = false;  // gated run: no candidate-area cell in the frame's row
  bool before_margin = false;  // single sequence: no earlier frame beyond match.margin yet
  int margin_frames = 0;       // match.margin
  double tau1 = 0.0;           // dird.tau1
  double dp_threshold = 0.0;   // tau3 * L
};

// match / score: status.best_j and its DP value (-1 / 0 when the frame has no stored entry).
FrameDetection match_detection(const FrameMatchStatus& status, const MatchOutcomeContext& context);

}  // namespace loopgate
