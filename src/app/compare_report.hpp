// What `compare` reports from its runs' summaries: the time parts, the table, the full / gated ratios, the
// ground truth's counts and the header line.
#pragma once

#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace loopgate::app {

// The run's time by kind of work (summary.json "time_accounting", pipeline/time_accounting.hpp): thread
// CPU time in ms, images decoded inside describe booked as decode, the method's end-of-stream work as match,
// so that each row holds the same work in every column and decode + describe + match + rest = total.
struct TimeParts {
  double decode_ms = 0, describe_ms = 0, match_ms = 0, rest_ms = 0, total_ms = 0;
  double describe_and_match_ms() const { return describe_ms + match_ms; }
  double with_decode_ms() const { return decode_ms + describe_ms + match_ms; }
};
TimeParts time_parts(const nlohmann::json& summary);
nlohmann::json time_parts_json(const TimeParts& t);

// The paper's Fig. 8 (KITTI 00): "the total time of loop-closure detection", 182 763.66 ms for pure DIRD and
// 28 329.93 ms with the pose constraint: feature extraction (its Fig. 7) and similarity, i.e. describe +
// match here. The paper does not say whether reading the images is in it; decode + describe + match is
// printed beside it.
inline constexpr const char* kTimeNote =
    "time: CPU time of the threads that did the work, summed over frames (a node body's thread and the "
    "threads of its parallel loops; a loaded machine does not inflate it); decode includes the images read "
    "inside describe, match the similarities full DIRD computes inside describe and the end-of-stream work, "
    "rest = sync, odometry, gate, sink; decode + describe + "
    "match + rest = total\n";
inline constexpr double kPaperFullMs = 182763.66;
inline constexpr double kPaperGatedMs = 28329.93;

// A summary number as text: integers as they are, others with `decimals`; "-" for null.
std::string number(const nlohmann::json& value, int decimals = 0);

// The table of the methods' figures, one column per method (two sequences: no time parts).
std::string table(const std::vector<std::string>& methods,
                  const std::map<std::string, nlohmann::json>& summaries, bool two_sequence);

// The full / gated ratios (time parts, wall time, descriptors, similarities, the paper's ratio, the gate's
// coverage) into `comparison`; returns their printed text.
std::string full_over_gated(const nlohmann::json& full, const nlohmann::json& gated,
                            nlohmann::json& comparison);

// The ground truth's loop query frames in 3-D, in the ground plane and before eval.min_travel_m (how much the
// counts depend on the rule: a drone's flight differs in 3-D; hovering is not a loop), into
// compare["truth_counts"]; returns their printed line ("" without such counts).
std::string truth_counts_text(const nlohmann::json& summary, nlohmann::json& compare);

// "compare on DATASET (N frames); ground-truth loops ...".
std::string compare_header(const std::string& dataset, const nlohmann::json& summary);

}  // namespace loopgate::app
