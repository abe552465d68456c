// SeqSLAM's result for one query (SeqSlamMatch) in the outputs' words: outcome (the vocabulary every method
// shares), its label ("no match", "rejected", "loop"), the best reference and ratio, and the reason text of
// frames.csv, for single- and two-sequence runs.
#pragma once

#include <cstddef>
#include <limits>

#include "core/types.hpp"
#include "stages/seqslam/seqslam.hpp"

namespace loopgate {

struct SeqSlamOutcomeContext {
  bool two_sequence = false;
  std::size_t query_count = 0;  // queries in the run (the "ends" of the sequence search)
  // Two sequences: frames in the reference sequence (a best sequence centred beyond the last one is no
  // match) and the dataset index of its first frame (for the message). Single sequence: unlimited.
  std::size_t reference_count = std::numeric_limits<std::size_t>::max();
  std::size_t reference_first = 0;
  // Gated SeqSLAM (single sequence): the search ran only inside the candidate areas; `outside_areas`: the
  // query's row has no covered cell.
  bool gated = false;
  bool outside_areas = false;
};

// outcome: no match -> kNoCandidate, rejected -> kBelowThreshold, loop -> kLoop. match / score: the best
// reference (index within the reference sequence) and the ratio, when there is a match.
FrameDetection seqslam_detection(const SeqSlamMatch& match, const SeqSlamConfig& config,
                                 const SeqSlamOutcomeContext& context);

}  // namespace loopgate
