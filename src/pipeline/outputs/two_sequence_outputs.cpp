#include "pipeline/outputs/two_sequence_outputs.hpp"

#include <array>
#include <string>
#include <vector>

#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "pipeline/loops/loops_writer.hpp"

namespace loopgate {

namespace {

// The run's frame ranges and datasets, as the outputs name frames.
struct Sides {
  const TwoSequenceInput& input;
  const AlignedSequences& ranges;

  bool aligned(std::size_t q, std::size_t r) const {
    return ranges.tolerance_frames >= 0 && ranges.aligned(q, r);
  }
  std::size_t query_number(std::size_t q) const {
    return input.query_dataset.source_index(ranges.query_first + q);
  }
  std::size_t reference_number(std::size_t r) const {
    return input.reference_dataset.source_index(ranges.reference_first + r);
  }
};

// loops.csv of the accepted loops. Returns how many lie within the tolerance of the aligned frame.
std::size_t write_loops(const Sides& sides, const std::vector<Detection>& loops,
                        const std::filesystem::path& out_dir) {
  const Dataset& query = sides.input.query_dataset;
  const Dataset& reference = sides.input.reference_dataset;
  LoopsWriter loops_csv;
  loops_csv.open(
      out_dir / "loops.csv", [&query](std::size_t frame) { return query.source_index(frame); },
      [&reference](std::size_t frame) { return reference.source_index(frame); });
  std::size_t aligned = 0;
  for (const Detection& loop : loops) {
    const std::size_t i = sides.ranges.query_first + loop.query;
    const std::size_t j = sides.ranges.reference_first + loop.reference;
    loops_csv.write(i, j, query.frame_t_ns(i), reference.frame_t_ns(j), loop.score);
    if (sides.aligned(loop.query, loop.reference)) ++aligned;
  }
  loops_csv.close();
  return aligned;
}

// frames.csv and the counts summary.json gives of it.
class QueryFramesCsv {
 public:
  QueryFramesCsv(const Sides& sides, const TwoSequenceMethod& method, const TwoSequenceMatches& matches,
                 const std::filesystem::path& out_dir)
      : sides_(sides), error_note_(method.error_note()) {
    QueryVerdict header;
    for (const std::string& column : matches.columns) header.cells.add(column, "");
    csv_.open(out_dir / "frames.csv", row(header, true).names());
  }

  void write(const QueryVerdict& verdict) {
    ++outcome_counts_[static_cast<std::size_t>(verdict.detection.outcome)];
    const std::int64_t match = verdict.detection.match;
    if (match >= 0 && sides_.aligned(verdict.query, static_cast<std::size_t>(match))) ++best_aligned_;
    frame_errors_ += sides_.input.query.errors[verdict.query].empty() ? 0 : 1;
    csv_.write_row(row(verdict, false).values());
  }
  void close() { csv_.close(); }

  std::size_t best_aligned() const { return best_aligned_; }
  std::size_t frame_errors() const { return frame_errors_; }
  // summary.json "detection": the queries by outcome.
  nlohmann::json detection_json() const {
    const auto count = [this](FrameOutcome o) { return outcome_counts_[static_cast<std::size_t>(o)]; };
    return {{"no_candidate", count(FrameOutcome::kNoCandidate)},
            {"below_threshold", count(FrameOutcome::kBelowThreshold)},
            {"suppressed", count(FrameOutcome::kSuppressed)},
            {"loop", count(FrameOutcome::kLoop)}};
  }

 private:
  // A query frame's row (the header: names only). A frame whose image failed gives the error before the
  // reason (with the method's note after it).
  CsvRow row(const QueryVerdict& verdict, bool header) const {
    CsvRow out;
    const std::size_t q = verdict.query;
    const Dataset& query = sides_.input.query_dataset;
    const std::size_t frame = sides_.ranges.query_first + q;
    const FrameDetection& detection = verdict.detection;
    const std::string& error = header ? error_note_ : sides_.input.query.errors[q];
    out.add("frame", header ? "" : std::to_string(query.source_index(frame)));
    out.add("t_ns", header ? "" : std::to_string(query.frame_t_ns(frame)));
    out.add("t_s", header ? "" : format_fixed(ns_to_s(query.frame_t_ns(frame)), 9));
    out.add("descriptor", header ? "" : sides_.input.query.valid[q] ? "y" : "n");
    out.add("detection", detection.label);
    out.add("match_frame",
            detection.match >= 0
                ? std::to_string(sides_.reference_number(static_cast<std::size_t>(detection.match)))
                : "");
    for (std::size_t k = 0; k < verdict.cells.names().size(); ++k)
      out.add(verdict.cells.names()[k], verdict.cells.values()[k]);
    out.add("status", error.empty() ? "ok" : "error");
    out.add("reason", error.empty() ? detection.reason : error + error_note_ + "; " + detection.reason);
    return out;
  }

  const Sides& sides_;
  std::string error_note_;
  CsvWriter csv_;
  std::array<std::size_t, 4> outcome_counts_{};
  std::size_t best_aligned_ = 0, frame_errors_ = 0;
};

// The evaluation block, and with a tolerance truth_loops.csv (dataset frame numbers: i query, j reference).
nlohmann::json evaluation(const Sides& sides, const TwoSequenceMethod& method,
                          const TwoSequenceMatches& matches, const std::filesystem::path& out_dir) {
  if (sides.ranges.tolerance_frames < 0) {
    return {{"available", false},
            {"why", "eval.aligned_tolerance_frames < 0: the sequences are not declared aligned"}};
  }
  CsvWriter truth_loops(out_dir / "truth_loops.csv", {"i", "j"});
  for (const auto& [q, r] : sides.ranges.pairs())
    truth_loops.write_row({std::to_string(sides.query_number(q)), std::to_string(sides.reference_number(r))});
  truth_loops.close();
  return evaluate_aligned(sides.ranges, matches.loops, matches.ranked, method.score_order());
}

nlohmann::json reference_errors_json(const DescribedFrames& reference) {
  constexpr std::size_t kMaxListed = 200;
  nlohmann::json errors = nlohmann::json::array();
  for (const std::string& e : reference.errors)
    if (!e.empty() && errors.size() < kMaxListed) errors.push_back(e);
  return errors;
}

nlohmann::json sequences_json(const Sides& sides) {
  const AlignedSequences& r = sides.ranges;
  return {{"reference",
           {{"root", sides.input.reference_dataset.root().string()},
            {"first_frame", r.reference_first},
            {"last_frame", r.reference_first + r.reference_count}}},
          {"query",
           {{"root", sides.input.query_dataset.root().string()},
            {"first_frame", r.query_first},
            {"last_frame", r.query_first + r.query_count}}}};
}

}  // namespace

nlohmann::json write_two_sequence_outputs(const TwoSequenceMethod& method, const TwoSequenceMatches& matches,
                                          const TwoSequenceInput& input, const AlignedSequences& ranges,
                                          const std::filesystem::path& out_dir) {
  const Sides sides{input, ranges};
  const std::size_t loops_aligned = write_loops(sides, matches.loops, out_dir);
  QueryFramesCsv frames(sides, method, matches, out_dir);
  for (const QueryVerdict& verdict : matches.frames) frames.write(verdict);
  frames.close();

  nlohmann::json summary = matches.summary;
  nlohmann::json detection = frames.detection_json();
  if (summary.contains("detection")) detection.update(summary["detection"]);
  const std::size_t described = input.reference.described + input.query.described;
  summary.update({
      {"mode", "two-sequence"},
      {"method", method.name()},
      {"score_order", std::string(enum_name(method.score_order()))},
      {"config", method.config_json()},
      {"images_decoded", described},
      {"descriptors_computed", described},  // SeqSLAM: preprocessed images
      {"similarities_computed", matches.similarities},
      {"loops", matches.loops.size()},
      {"query_frames", ranges.query_count},
      {"query_frames_with_error", frames.frame_errors()},
      {"reference_errors", reference_errors_json(input.reference)},
      {"detection", std::move(detection)},
      {"evaluation", evaluation(sides, method, matches, out_dir)},
  });
  summary.update(sequences_json(sides));
  if (ranges.tolerance_frames >= 0) {
    summary["aligned"] = {{"tolerance_frames", ranges.tolerance_frames},
                          {"loops_within_tolerance", loops_aligned},
                          {"loops_beyond_tolerance", matches.loops.size() - loops_aligned},
                          {"best_match_within_tolerance", frames.best_aligned()}};
  }
  return summary;
}

}  // namespace loopgate
