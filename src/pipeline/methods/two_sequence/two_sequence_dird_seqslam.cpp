// dird-seqslam's two-sequence form (docs/illumination.md): the descriptors of both sequences, each coded with
// its own statistics, the distance of every (query, reference) pair (coded_distance, or the compact codes of
// dird_seqslam.code, as in the single-sequence run), then the contrast-enhanced sequence search query by
// query (ContrastSequenceSearch in two-sequence mode: no margin). Every query's best line is its verdict,
// accepted or not, and the PR sweep runs over them; the loops are the accepted ones (score = mean z, higher
// is better).
#include <algorithm>
#include <optional>

#include "core/stop_request.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "pipeline/methods/coded_distance.hpp"
#include "pipeline/methods/two_sequence/dird_sequences.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "stages/dird/dird_codes.hpp"
#include "stages/match/contrast_search.hpp"

namespace loopgate {

namespace {

// Distances in blocks of this many queries (in parallel), each block then searched in query order: memory
// for one block of rows, not the whole matrix.
constexpr std::size_t kQueryBlock = 256;

class DirdSeqSlamTwoSequence final : public TwoSequenceMethod {
 public:
  explicit DirdSeqSlamTwoSequence(const PipelineConfig& config)
      : config_(config),
        dird_(config.dird_seqslam.descriptor(config.dird)),
        standardize_(config.dird_seqslam.standardization(config.standardize)),
        sequences_(dird_) {
    // The viewpoint tolerance warps query-row frames inside a single-sequence run; this form has no such
    // row, so it refuses the setting rather than running without it.
    if (config.dird_seqslam.viewpoint.enabled()) {
      throw ConfigError(
          "dird_seqslam.viewpoint_lateral_m: the viewpoint tolerance works in a single-sequence run only; "
          "a two-sequence run (--reference/--query) does not apply it: set it to 0");
    }
  }

  const char* name() const override { return "dird-seqslam"; }
  ScoreOrder score_order() const override { return ScoreOrder::kHigherIsBetter; }
  nlohmann::json config_json() const override { return config_to_json(config_); }
  void begin(std::size_t reference_count, std::size_t query_count) override {
    sequences_.begin(reference_count, query_count);
  }
  bool describe(SequenceSide side, std::size_t k, const cv::Mat* image, const Dataset& /*dataset*/,
                std::size_t /*frame*/, std::string& /*error*/) override {
    return sequences_.describe(side, k, image);
  }

  TwoSequenceMatches match(TwoSequenceRun& run, const TwoSequenceInput& input) override {
    std::int64_t t0 = run.now_ns();
    code(input);
    const double code_s = seconds_between(t0, run.now_ns());
    run.phase("code (reference and query)", t0);

    double distance_s = 0.0, search_s = 0.0;
    ContrastSequenceSearch search(config_.dird_seqslam.search, config_.match.sequence_length,
                                  ContrastSequenceSearch::Mode::kTwoSequence, 0, 0);
    ContrastOutput output;
    std::vector<std::vector<DistanceEntry>> rows(std::min(kQueryBlock, input.query_count));
    for (std::size_t first = 0; first < input.query_count; first += kQueryBlock) {
      const std::size_t count = std::min(kQueryBlock, input.query_count - first);
      t0 = run.now_ns();
      run.parallel(
          count,
          [&](std::size_t k) {
            const std::size_t q = first + k;
            rows[k].clear();
            if (!input.query.valid[q]) return;
            rows[k].reserve(input.reference_count);
            for (std::size_t r = 0; r < input.reference_count; ++r) {
              if (input.reference.valid[r]) rows[k].push_back({static_cast<std::int64_t>(r), distance(q, r)});
            }
          },
          "distances");
      distance_s += seconds_between(t0, run.now_ns());
      run.phase("distances (query block)", t0);
      t0 = run.now_ns();
      stop_request::check_abort("two-sequence run");  // a second stop signal aborts the search
      for (std::size_t k = 0; k < count; ++k)
        search.push(static_cast<std::int64_t>(first + k), rows[k], output);
      search_s += seconds_between(t0, run.now_ns());
      run.phase("search (query block)", t0);
    }
    t0 = run.now_ns();
    search.flush(output);
    search_s += seconds_between(t0, run.now_ns());
    run.phase("search flush", t0);

    TwoSequenceMatches out = verdicts(output, input);
    out.similarities = input.reference.described * input.query.described;  // distances
    out.summary = {
        {"detection", {{"delay_frames", search.emission_delay()}}},
        {"dird_seqslam",
         {{"normalization", enum_name(dird_.normalization)},
          {"resize", enum_name(dird_.resize)},
          {"velocities", config_.dird_seqslam.search.velocities()},
          {"sequence_length", search.sequence_length()}}},
        {"stages_s", {{"code", code_s}, {"distances", distance_s}, {"search", search_s}}},
    };
    if (standardize_.enabled()) out.summary["standardize"] = standardize_json(standardize_, *ref_, *qry_);
    return out;
  }

 private:
  // The codes of both sequences, and with dird_seqslam.code sign or ternary their compact codes.
  void code(const TwoSequenceInput& input) {
    ref_ = code_sequence(sequences_.of(SequenceSide::kReference), input.reference.valid, standardize_);
    qry_ = code_sequence(sequences_.of(SequenceSide::kQuery), input.query.valid, standardize_);
    if (!config_.dird_seqslam.codes.compact()) return;
    const auto compact = [&](const CodedSequence& coded, const DescribedFrames& described) {
      CompactCodeMatrix m(config_.dird_seqslam.codes, standardize_.clamp_sigma,
                          std::max<std::size_t>(1, coded.codes.size()));
      for (std::size_t k = 0; k < coded.codes.size(); ++k)
        if (described.valid[k]) m.set(k, coded.codes[k]);
      return m;
    };
    ref_compact_.emplace(compact(*ref_, input.reference));
    qry_compact_.emplace(compact(*qry_, input.query));
  }

  double distance(std::size_t q, std::size_t r) const {
    return qry_compact_ ? qry_compact_->distance(q, *ref_compact_, r)
                        : coded_distance(dird_, standardize_, qry_->codes[q], qry_->norms[q], ref_->codes[r],
                                         ref_->norms[r]);
  }

  // A query frame's cells of frames.csv: its best line's score, velocity and last query frame.
  static void add_cells(const ContrastVerdict& verdict, const TwoSequenceInput* input, CsvRow& row) {
    const bool has_best = verdict.best_j >= 0 && input;
    row.add("match_score", has_best ? format_fixed(verdict.score, 6) : "");
    row.add("velocity", has_best ? format_fixed(verdict.velocity, 4) : "");
    row.add("line_end_frame", has_best ? std::to_string(input->query_dataset.source_index(
                                             input->query_first + static_cast<std::size_t>(verdict.line_end)))
                                       : "");
  }

  TwoSequenceMatches verdicts(const ContrastOutput& output, const TwoSequenceInput& input) const {
    TwoSequenceMatches out;
    CsvRow header;
    add_cells(ContrastVerdict{}, nullptr, header);
    out.columns = header.names();
    for (const LoopClosure& loop : output.loops) {  // within the ranges, score = mean z
      out.loops.push_back(
          Detection{static_cast<std::size_t>(loop.i), static_cast<std::size_t>(loop.j), loop.score});
    }
    for (const ContrastVerdict& verdict : output.frames) {
      const auto q = static_cast<std::size_t>(verdict.i);
      ContrastOutcomeContext context;
      context.two_sequence = true;
      context.described = input.query.valid[q] != 0;
      context.min_score = config_.dird_seqslam.search.min_score;
      if (verdict.best_j >= 0)
        out.ranked.push_back(Detection{q, static_cast<std::size_t>(verdict.best_j), verdict.score});
      QueryVerdict row{q, contrast_detection(verdict, context), {}};
      add_cells(verdict, &input, row.cells);
      out.frames.push_back(std::move(row));
    }
    return out;
  }

  const PipelineConfig& config_;
  DirdConfig dird_;
  StandardizeConfig standardize_;
  DirdSequences sequences_;
  std::optional<CodedSequence> ref_, qry_;
  std::optional<CompactCodeMatrix> ref_compact_, qry_compact_;
};

}  // namespace

std::unique_ptr<TwoSequenceMethod> make_two_sequence_dird_seqslam(const PipelineConfig& config) {
  return std::make_unique<DirdSeqSlamTwoSequence>(config);
}

}  // namespace loopgate
