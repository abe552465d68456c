// The outputs of a two-sequence run (two_sequence.hpp), written from its method's matches, the same for
// every method:
//   frames.csv       one row per query frame: the columns of every method (frame, t_ns, t_s, descriptor,
//                    detection, match_frame), the method's own, then status and reason;
//   loops.csv        i,j,t_i,t_j,score (i query frame, j reference frame, dataset frame numbers);
//   truth_loops.csv  with eval.aligned_tolerance_frames >= 0: the aligned pairs (i query, j reference);
// and summary.json's fields: counts, the evaluation (evaluate_aligned; {"available": false} without a
// tolerance), the sequences, "aligned" and the method's own (stages_s, detection, ...).
#pragma once

#include <filesystem>
#include <nlohmann/json.hpp>

#include "eval/run_evaluation.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"

namespace loopgate {

// `ranges`: the frame ranges run (query_count: the query frames matched), with the tolerance. Returns
// summary.json without the run's wall time, peak memory, provenance and interruption.
nlohmann::json write_two_sequence_outputs(const TwoSequenceMethod& method, const TwoSequenceMatches& matches,
                                          const TwoSequenceInput& input, const AlignedSequences& ranges,
                                          const std::filesystem::path& out_dir);

}  // namespace loopgate
