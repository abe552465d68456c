#include "stages/seqslam/seqslam_outcome.hpp"

#include <spdlog/fmt/fmt.h>

#include <cmath>

namespace loopgate {

FrameDetection seqslam_detection(const SeqSlamMatch& m, const SeqSlamConfig& config,
                                 const SeqSlamOutcomeContext& context) {
  const std::size_t half = static_cast<std::size_t>(config.sequence_length_frames / 2);
  const std::size_t q = m.query;
  const bool near_end = q < half || q + half >= context.query_count;
  const double threshold = config.ratio_threshold;
  FrameDetection d;
  if (!m.has_match || m.reference >= context.reference_count) {
    d.outcome = FrameOutcome::kNoCandidate;
    d.label = "no match";
    if (context.two_sequence) {
      d.reason = near_end ? fmt::format("within ds/2 = {} frames of an end of the query sequence", half)
                 : m.has_match
                     ? fmt::format("best sequence centred on reference {} beyond the last reference frame",
                                   context.reference_first + m.reference)
                     : std::string("no sequence with a finite score");
    } else if (context.outside_areas) {
      d.reason = "outside every candidate area";
    } else if (near_end) {
      d.reason = fmt::format("within ds/2 = {} frames of an end of the run", half);
    } else {
      d.reason = fmt::format("every sequence{} touches the exclusion ({} {} frames)",
                             context.gated ? " matching a candidate-area cell" : "",
                             enum_name(config.exclusion), config.exclusion_margin_frames);
    }
    return d;
  }
  d.match = static_cast<std::int64_t>(m.reference);
  d.score = m.ratio;
  if (m.accepted) {
    d.outcome = FrameOutcome::kLoop;
    d.label = "loop";
    d.reason = fmt::format("ratio {:.4f} <= {:.4f}", m.ratio, threshold);
  } else {
    d.outcome = FrameOutcome::kBelowThreshold;
    d.label = "rejected";
    d.reason = !context.two_sequence || std::isfinite(m.ratio)
                   ? fmt::format("ratio {:.4f} > {:.4f}", m.ratio, threshold)
                   : fmt::format("no sequence outside best +- {} rows: no second best, no support",
                                 config.second_best_window_rows / 2);
  }
  return d;
}

}  // namespace loopgate
