// The DIRD descriptors of the two sequences of a two-sequence run (the two-sequence forms of dird and
// dird-seqslam), by index within their range, and their codes: each sequence standardised with statistics
// of its own (docs/standardize.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <opencv2/core/mat.hpp>
#include <string>
#include <vector>

#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "stages/dird/dird_extractor.hpp"
#include "stages/dird/dird_standardize.hpp"

namespace loopgate {

class DirdSequences {
 public:
  explicit DirdSequences(const DirdConfig& dird) : extractor_(dird) {}

  void begin(std::size_t reference_count, std::size_t query_count) {
    reference_.resize(reference_count);
    query_.resize(query_count);
  }
  // Frame k of `side`: its descriptor, or all zeros when there is no image (false).
  bool describe(SequenceSide side, std::size_t k, const cv::Mat* image);
  const std::vector<Descriptor>& of(SequenceSide side) const {
    return side == SequenceSide::kReference ? reference_ : query_;
  }

 private:
  DirdExtractor extractor_;
  std::vector<Descriptor> reference_, query_;
};

// The codes the distances are computed on, one sequence with statistics of its own: standardize.mode off: the
// raw descriptors; batch: the statistics of the whole sequence; causal: the causal rule over the sequence's
// frames in order (every observe_every-th frame observed; frames before the warm-up take the first
// snapshot). A sequence too short for the causal warm-up takes its batch statistics (said in `note`).
// Frames without a descriptor stay uncoded.
struct CodedSequence {
  std::vector<Descriptor> codes;
  std::vector<double> norms;  // standard_norm of the codes (cosine)
  std::string statistics;     // "raw", "batch", "causal"
  std::string note;
};
CodedSequence code_sequence(const std::vector<Descriptor>& descriptors,
                            const std::vector<std::uint8_t>& valid, const StandardizeConfig& config);

// summary.json "standardize" of a two-sequence run: mode, distance, the statistics of each side, notes.
nlohmann::json standardize_json(const StandardizeConfig& standardize, const CodedSequence& reference,
                                const CodedSequence& query);

}  // namespace loopgate
