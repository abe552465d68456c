#include "stages/match/match_outcome.hpp"

#include <spdlog/fmt/fmt.h>

namespace loopgate {

namespace {

std::string no_candidate_reason(const MatchOutcomeContext& c) {
  if (c.outside_areas) return "outside every candidate area";
  if (!c.described) return "no descriptor (image not decoded)";
  if (c.before_margin) return fmt::format("no earlier frame beyond the margin of {}", c.margin_frames);
  return fmt::format("no similarity above tau1 = {}", c.tau1);
}

}  // namespace

FrameDetection match_detection(const FrameMatchStatus& status, const MatchOutcomeContext& context) {
  FrameDetection d;
  d.outcome = status.outcome;
  d.label = to_string(status.outcome);
  if (status.best_j >= 0) {
    d.match = status.best_j;
    d.score = status.best_score;
  }
  const double threshold = context.dp_threshold;
  switch (status.outcome) {
    case FrameOutcome::kNoCandidate: d.reason = no_candidate_reason(context); break;
    case FrameOutcome::kBelowThreshold:
      d.reason = context.two_sequence
                     ? fmt::format("best DP {:.4f} <= {:.4f}", status.best_score, threshold)
                     : fmt::format("{} candidates, best similarity {:.4f}; best DP {:.4f} <= {:.4f}",
                                   status.candidates, status.best_similarity, status.best_score, threshold);
      break;
    case FrameOutcome::kSuppressed:
      d.reason =
          fmt::format("{} DP values above {:.4f}, all suppressed by NMS", status.above_threshold, threshold);
      break;
    case FrameOutcome::kLoop:
      d.reason = context.two_sequence ? fmt::format("{} loop closure(s)", status.loops)
                                      : fmt::format("{} loop closure(s) of {} DP values above {:.4f}",
                                                    status.loops, status.above_threshold, threshold);
      break;
  }
  return d;
}

}  // namespace loopgate
