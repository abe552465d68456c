// SeqSLAM's two-sequence form (docs/detection.md § SeqSLAM): step 1 on both sequences (the run's parallel
// describe) into one SeqSlamBatch, the store the single-sequence method uses, reference first; then the
// difference matrix (reference rows x query columns), contrast enhancement and sequence search with exclusion
// "none" whatever seqslam.exclusion says (logged). Every query's best reference match and its ratio is its
// verdict, accepted or not; the loops are the accepted ones (score = ratio, lower is better). A frame that
// does not decode or preprocess takes part as an all-zero image (SeqSlamBatch::add_missing).
#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "core/error.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/writers.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/methods/seqslam_batch.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "stages/seqslam/seqslam_outcome.hpp"

namespace loopgate {

namespace {

// A query frame's cells of frames.csv (the header: no match).
void add_cells(const SeqSlamMatch* m, CsvRow& row) {
  row.add("match_score", m ? format_fixed(m->ratio, 6) : "");
  row.add("best_score", m ? format_fixed(m->best_score, 6) : "");
  row.add("second_score", m ? format_fixed(m->second_score, 6) : "");
}

class SeqSlamTwoSequence final : public TwoSequenceMethod {
 public:
  explicit SeqSlamTwoSequence(const PipelineConfig& config) : effective_(config) {
    if (effective_.seqslam.exclusion != SeqSlamExclusionKind::kNone) {
      spdlog::warn(
          "two-sequence mode: seqslam.exclusion '{}' ignored, using 'none' (reference and query are "
          "different runs, every pair may match)",
          enum_name(effective_.seqslam.exclusion));
      effective_.seqslam.exclusion = SeqSlamExclusionKind::kNone;
    }
  }

  const char* name() const override { return "seqslam"; }
  ScoreOrder score_order() const override { return ScoreOrder::kLowerIsBetter; }
  nlohmann::json config_json() const override { return config_to_json(effective_); }
  const char* describe_step() const override { return "preprocess"; }
  std::string error_note() const override { return " (took part as an all-zero image)"; }

  void begin(std::size_t reference_count, std::size_t query_count) override {
    reference_count_ = reference_count;
    batch_.emplace(effective_.seqslam, reference_count + query_count);
  }

  bool describe(SequenceSide side, std::size_t k, const cv::Mat* image, const Dataset& dataset,
                std::size_t frame, std::string& error) override {
    const std::size_t seq = (side == SequenceSide::kReference ? 0 : reference_count_) + k;
    if (image) {
      try {
        batch_->add(seq, *image);
        return true;
      } catch (const std::invalid_argument& e) {
        error = fmt::format("seqslam preprocessing of {}: {}", dataset.image_path(frame).string(), e.what());
      }
    }
    batch_->add_missing(seq);
    return false;
  }

  TwoSequenceMatches match(TwoSequenceRun& run, const TwoSequenceInput& input) override {
    const std::pair<const Dataset*, const DescribedFrames*> sides[] = {
        {&input.reference_dataset, &input.reference}, {&input.query_dataset, &input.query}};
    for (const auto& [dataset, described] : sides) {
      if (described->described == 0 && input.query_count > 0) {
        const auto first_error = std::find_if(described->errors.begin(), described->errors.end(),
                                              [](const std::string& e) { return !e.empty(); });
        throw DataError(dataset->root(), "SeqSLAM: no image of the sequence could be preprocessed (" +
                                             (first_error != described->errors.end() ? *first_error : "") +
                                             ")");
      }
    }
    const std::int64_t t0 = run.now_ns();
    std::vector<SeqSlamMatch> matches;
    if (input.query_count > 0) matches = batch_->run_two_sequence(input.reference_count, input.query_count);
    const double search_s = seconds_between(t0, run.now_ns());
    run.phase("search (SeqSLAM)", t0);

    TwoSequenceMatches out;
    CsvRow header;
    add_cells(nullptr, header);
    out.columns = header.names();
    SeqSlamOutcomeContext context;
    context.two_sequence = true;
    context.query_count = input.query_count;
    context.reference_count = input.reference_count;
    context.reference_first = input.reference_first;
    for (std::size_t q = 0; q < input.query_count; ++q) {
      const SeqSlamMatch& m = matches.at(q);
      QueryVerdict verdict{q, seqslam_detection(m, effective_.seqslam, context), {}};
      const bool has_match = verdict.detection.match >= 0;
      if (has_match) {
        if (std::isfinite(m.ratio)) out.ranked.push_back(Detection{q, m.reference, m.ratio});
        if (verdict.detection.outcome == FrameOutcome::kLoop)
          out.loops.push_back(Detection{q, m.reference, m.ratio});
      }
      add_cells(has_match ? &m : nullptr, verdict.cells);
      out.frames.push_back(std::move(verdict));
    }
    out.similarities = input.reference_count * input.query_count;  // difference matrix entries
    out.summary = {{"stages_s", {{"search", search_s}}}};
    return out;
  }

 private:
  PipelineConfig effective_;  // seqslam.exclusion "none"
  std::size_t reference_count_ = 0;
  std::optional<SeqSlamBatch> batch_;
};

}  // namespace

std::unique_ptr<TwoSequenceMethod> make_two_sequence_seqslam(const PipelineConfig& config) {
  return std::make_unique<SeqSlamTwoSequence>(config);
}

std::unique_ptr<TwoSequenceMethod> make_two_sequence_method(const PipelineConfig& config) {
  // The detector's row of mode full: a two-sequence run has no gate, and DIRD's rows share one form that
  // standardises as standardize.mode says (batch included).
  const MethodEntry* entry = find_method_entry(enum_name(config.run.method), "full", "off");
  if (entry == nullptr || entry->two_sequence == nullptr) {
    throw ConfigError("run.method: '" + std::string(enum_name(config.run.method)) +
                      "' has no two-sequence form (two-sequence methods: " + method_entry_names(true) + ")");
  }
  return entry->two_sequence(config);
}

}  // namespace loopgate
