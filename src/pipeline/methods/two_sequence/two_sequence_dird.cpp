// DIRD's two-sequence form (docs/detection.md § Two sequences): the descriptors of both sequences, S for
// every (reference r, query q) pair with no safety margin, and the query rows through the streaming
// SequenceMatcher in its two-sequence mode (the DP and NMS of the single-sequence run; i = query frame, j =
// reference frame). Raw descriptors use dird.mu / dird.sigma and DirdSimilarity's rows, as the full DIRD
// method does; standardised (standardize.mode batch or causal), each sequence is coded with its own
// statistics and the logistic of standard_default_scale() is applied to their distances. scale.mode online:
// the logistic from the distances of every (reference, query) pair by the rule of OnlineScale
// (dird_online_scale.hpp; the no-revisit rule of `loopgate calibrate`), a first pass over the pairs.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <mutex>
#include <optional>
#include <span>

#include "io/config.hpp"
#include "io/writers.hpp"
#include "pipeline/methods/coded_distance.hpp"
#include "pipeline/methods/two_sequence/dird_sequences.hpp"
#include "pipeline/methods/two_sequence/two_sequence_method.hpp"
#include "stages/dird/dird_online_scale.hpp"
#include "stages/dird/dird_similarity.hpp"
#include "stages/match/match_outcome.hpp"
#include "stages/match/sequence_matcher.hpp"

namespace loopgate {

namespace {

// A query frame's cells of frames.csv (the header: a default status).
void add_cells(const FrameMatchStatus& status, CsvRow& row) {
  row.add("match_score", status.best_j >= 0 ? format_fixed(status.best_score, 6) : "");
  row.add("best_similarity", format_fixed(status.best_similarity, 6));
  row.add("candidates", std::to_string(status.candidates));
}

class DirdTwoSequence final : public TwoSequenceMethod {
 public:
  explicit DirdTwoSequence(const PipelineConfig& config)
      : config_(config), sequences_(config.dird), similarity_(config.dird) {}

  const char* name() const override { return "dird"; }
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
    TwoSequenceMatches out;
    std::vector<std::vector<SimilarityEntry>> rows = similarity_rows(run, input);
    const double similarity_s = seconds_between(t0, run.now_ns());
    run.phase("similarities", t0);
    out.similarities = input.query.described * input.reference.described;

    t0 = run.now_ns();
    SequenceMatcher matcher(config_.match, SequenceMatcher::Mode::kTwoSequence, 0);
    MatchOutput output;
    for (std::size_t q = 0; q < input.query_count; ++q) {
      matcher.push(static_cast<std::int64_t>(q), rows[q], output);
      rows[q] = {};
    }
    matcher.flush(output);
    const double match_s = seconds_between(t0, run.now_ns());
    run.phase("match (sequence matcher)", t0);

    CsvRow header;
    add_cells(FrameMatchStatus{}, header);
    out.columns = header.names();
    for (const LoopClosure& loop : output.loops) {  // score = DP
      out.loops.push_back(
          Detection{static_cast<std::size_t>(loop.i), static_cast<std::size_t>(loop.j), loop.score});
    }
    out.ranked = out.loops;
    for (const FrameMatchStatus& status : output.frames) {
      MatchOutcomeContext context;
      context.two_sequence = true;
      context.described = input.query.valid[static_cast<std::size_t>(status.i)] != 0;
      context.tau1 = config_.dird.tau1;
      context.dp_threshold = config_.match.dp_threshold();
      QueryVerdict verdict{static_cast<std::size_t>(status.i), match_detection(status, context), {}};
      add_cells(status, verdict.cells);
      out.frames.push_back(std::move(verdict));
    }
    out.summary = {
        {"detection", {{"nms_delay_frames", matcher.emission_delay()}}},
        {"stages_s", {{"similarity", similarity_s}, {"match", match_s}}},
        {"scale",
         {{"mode", enum_name(config_.scale.mode)},
          {"mu", scale_.mu},
          {"sigma", scale_.sigma},
          {"cutoff_distance", scale_.cutoff_distance},
          {"estimated", scale_.estimated},
          {"distances", scale_distances_}}},
    };
    if (standardized_) out.summary["standardize"] = *standardized_;
    return out;
  }

 private:
  // Similarity rows of every query against the whole reference (no margin), in parallel; frames without a
  // descriptor take part in no pair.
  std::vector<std::vector<SimilarityEntry>> similarity_rows(TwoSequenceRun& run,
                                                            const TwoSequenceInput& input) {
    const std::vector<Descriptor>& ref = sequences_.of(SequenceSide::kReference);
    const std::vector<Descriptor>& qry = sequences_.of(SequenceSide::kQuery);
    const DescribedFrames& ref_frames = input.reference;
    const DescribedFrames& qry_frames = input.query;
    const std::size_t ref_count = input.reference_count;
    std::optional<CodedSequence> ref_codes, qry_codes;
    if (config_.standardize.enabled()) {
      ref_codes = code_sequence(ref, ref_frames.valid, config_.standardize);
      qry_codes = code_sequence(qry, qry_frames.valid, config_.standardize);
      standardized_ = standardize_json(config_.standardize, *ref_codes, *qry_codes);
    }
    const auto distance_of = [&](std::size_t q, std::size_t r) {
      return qry_codes ? coded_distance(config_.dird, config_.standardize, qry_codes->codes[q],
                                        qry_codes->norms[q], ref_codes->codes[r], ref_codes->norms[r])
                       : similarity_.distance(qry[q], ref[r]);
    };
    const DirdConfig& dird = config_.dird;
    scale_ = qry_codes ? standard_default_scale(config_.standardize, dird.tau1)
                       : LogisticScale{dird.mu, dird.sigma,
                                       logistic_distance_at(dird.tau1, dird.mu, dird.sigma), false, 0};
    if (config_.scale.online()) estimate_scale(run, input, distance_of);
    std::vector<std::vector<SimilarityEntry>> rows(input.query_count);
    if (qry_codes || config_.scale.online()) {
      run.parallel(input.query_count, [&](std::size_t q) {
        if (!qry_frames.valid[q]) return;
        for (std::size_t r = 0; r < ref_count; ++r) {
          if (!ref_frames.valid[r]) continue;
          const double d = distance_of(q, r);
          if (d >= scale_.cutoff_distance) continue;
          const double sim = logistic_similarity(d, scale_.mu, scale_.sigma);
          if (sim > dird.tau1) rows[q].push_back({static_cast<std::int64_t>(r), sim});
        }
      });
      return rows;
    }
    const bool any_ref_missing = ref_frames.described != ref_count;
    run.parallel(input.query_count, [&](std::size_t q) {
      if (!qry_frames.valid[q]) return;
      similarity_.sparse_row(qry[q], ref.data(), ref_count, 0, rows[q]);
      if (any_ref_missing) {
        std::erase_if(rows[q], [&](const SimilarityEntry& e) {
          return !ref_frames.valid[static_cast<std::size_t>(e.j)];
        });
      }
    });
    return rows;
  }

  // scale.mode online: the scale from the distances of every described (reference, query) pair.
  template <class DistanceOf>
  void estimate_scale(TwoSequenceRun& run, const TwoSequenceInput& input, const DistanceOf& distance_of) {
    OnlineScale online(config_.scale, config_.dird.tau1, scale_);
    std::mutex online_mutex;
    run.parallel(input.query_count, [&](std::size_t q) {
      if (!input.query.valid[q]) return;
      std::vector<double> distances;
      distances.reserve(input.reference_count);
      for (std::size_t r = 0; r < input.reference_count; ++r) {
        if (input.reference.valid[r]) distances.push_back(distance_of(q, r));
      }
      const std::lock_guard lock(online_mutex);
      online.add(std::span<const double>(distances));
    });
    scale_distances_ = online.count();
    scale_ = online.scale();
    if (!scale_.estimated) {
      spdlog::warn(
          "scale.mode online: {} pair distances are too few for an estimate (scale.min_distances {}): "
          "the configured scale is used",
          online.count(), config_.scale.min_distances);
    }
    spdlog::info("scale: mu {:.6g}, sigma {:.6g}, cut-off {:.6g} ({} from {} pair distances)", scale_.mu,
                 scale_.sigma, scale_.cutoff_distance, scale_.estimated ? "estimated" : "prior",
                 online.count());
  }

  const PipelineConfig& config_;
  DirdSequences sequences_;
  DirdSimilarity similarity_;
  LogisticScale scale_;
  std::int64_t scale_distances_ = 0;
  std::optional<nlohmann::json> standardized_;
};

}  // namespace

std::unique_ptr<TwoSequenceMethod> make_two_sequence_dird(const PipelineConfig& config) {
  return std::make_unique<DirdTwoSequence>(config);
}

}  // namespace loopgate
