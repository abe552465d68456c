#include "eval/run_evaluation.hpp"

#include <algorithm>
#include <cstdlib>

namespace loopgate {

nlohmann::json loop_evaluation_json(const std::vector<Detection>& loops, const std::vector<Detection>& ranked,
                                    const LoopGroundTruth& truth, ScoreOrder score_order) {
  PrConfig pr_config;
  pr_config.score_order = score_order;
  const PrResult pr = evaluate_precision_recall(ranked, truth, pr_config);
  // Loops at the same place without travel (hovering, a stop) are neither true nor false: counted apart.
  const std::vector<Detection> judged = judged_detections(loops, truth);
  std::size_t loops_true = 0, best_true = 0;
  for (const Detection& d : judged) loops_true += truth.is_true_match(d.query, d.reference) ? 1 : 0;
  const std::vector<Detection> best = best_detection_per_query(judged, pr_config.lower_is_better());
  for (const Detection& d : best) best_true += truth.is_true_match(d.query, d.reference) ? 1 : 0;
  // R@1: positives whose top-ranked judged candidate (accepted or not) is a true match.
  std::size_t top1_true = 0;
  for (const Detection& d :
       best_detection_per_query(judged_detections(ranked, truth), pr_config.lower_is_better())) {
    if (truth.is_positive(d.query) && truth.is_true_match(d.query, d.reference)) ++top1_true;
  }
  nlohmann::json curve = nlohmann::json::array();
  for (const PrPoint& point : pr.curve) {
    curve.push_back({{"threshold", point.threshold},
                     {"precision", point.precision},
                     {"recall", point.recall},
                     {"detections", point.detections},
                     {"true_positives", point.true_positives}});
  }
  return {{"loop_truth",
           {{"loops", loops.size()},
            {"loops_true", loops_true},
            {"loops_false", judged.size() - loops_true},
            {"loops_without_travel", loops.size() - judged.size()},
            {"query_frames_with_loops", best.size()},
            {"query_best_loop_true", best_true},
            {"query_best_loop_false", best.size() - best_true}}},
          {"precision_recall",
           {{"score_order", std::string(enum_name(pr_config.score_order))},
            {"positives", pr.positives},
            {"queries_with_detection", pr.queries_with_detection},
            {"not_judged_without_travel", pr.not_judged},
            {"average_precision", pr.average_precision},
            {"recall_at_100", pr.recall_at_100},
            {"recall_at_99", pr.recall_at_99},
            {"recall_at_95", pr.recall_at_95},
            {"recall_at_1",
             pr.positives == 0 ? 0.0 : static_cast<double>(top1_true) / static_cast<double>(pr.positives)},
            {"curve", curve}}}};
}

SequenceEvaluation evaluate_sequence(const SequenceEvaluationInput& input) {
  SequenceEvaluation out;
  if (input.pairs) {
    out.truth = LoopGroundTruth::from_pairs(input.frame_count, *input.pairs);
    nlohmann::json truth = input.pairs_truth.is_object() ? input.pairs_truth : nlohmann::json::object();
    truth["positives"] = out.truth.positive_count();
    out.json = {{"available", true}, {"truth", truth}};
  } else {
    out.truth = LoopGroundTruth::from_positions(input.p_w, input.truth);
    out.json = {{"available", true},
                {"truth",
                 {{"radius_m", input.truth.radius_m},
                  {"gap_frames", input.truth.gap_frames},
                  {"plane", std::string(enum_name(input.truth.plane))},
                  {"accept_radius_m", input.truth.effective_accept_radius_m()},
                  {"min_travel_m", input.truth.revisit.min_travel_m},
                  {"positives", out.truth.positive_count()}}}};
  }
  out.truth_pairs = out.truth.pairs();
  out.json.update(loop_evaluation_json(input.loops, input.ranked, out.truth, input.score_order));
  return out;
}

nlohmann::json gate_coverage_json(const std::vector<Eigen::Vector3d>& p_w, const GroundTruthConfig& truth,
                                  int margin_frames, const std::function<bool(std::size_t)>& processed,
                                  const std::function<bool(std::size_t, std::size_t)>& covers) {
  GroundTruthConfig reachable_config = truth;
  reachable_config.gap_frames = std::max(truth.gap_frames, margin_frames);
  return gate_coverage_json(LoopGroundTruth::from_positions(p_w, reachable_config),
                            reachable_config.gap_frames, processed, covers);
}

nlohmann::json gate_coverage_json(const LoopGroundTruth& truth, int min_gap_frames,
                                  const std::function<bool(std::size_t)>& processed,
                                  const std::function<bool(std::size_t, std::size_t)>& covers) {
  const auto gap = static_cast<std::size_t>(std::max(0, min_gap_frames));
  std::size_t positives = 0, covered = 0;
  for (std::size_t q = 0; q < truth.frame_count(); ++q) {
    if (!truth.is_positive(q) || !processed(q)) continue;
    const std::vector<std::size_t>& references = truth.true_references(q);
    if (std::none_of(references.begin(), references.end(), [&](std::size_t r) { return r + gap <= q; }))
      continue;
    ++positives;
    for (const std::size_t r : references) {
      if (r + gap <= q && processed(r) && covers(q, r)) {
        ++covered;
        break;
      }
    }
  }
  return {
      {"gap_frames", min_gap_frames},
      {"positive_query_frames", positives},
      {"covered_query_frames", covered},
      {"covered_fraction", positives ? static_cast<double>(covered) / static_cast<double>(positives) : 0.0}};
}

bool AlignedSequences::aligned(std::size_t q, std::size_t r) const {
  return tolerance_frames >= 0 && std::llabs(static_cast<long long>(query_first + q) -
                                             static_cast<long long>(reference_first + r)) <= tolerance_frames;
}

std::vector<std::pair<std::size_t, std::size_t>> AlignedSequences::pairs() const {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  if (tolerance_frames < 0) return out;
  const auto tolerance = static_cast<std::size_t>(tolerance_frames);
  for (std::size_t q = 0; q < query_count; ++q) {
    const std::size_t frame = query_first + q;
    const std::size_t lo = std::max(reference_first, frame >= tolerance ? frame - tolerance : 0);
    const std::size_t hi = std::min(reference_first + reference_count, frame + tolerance + 1);
    for (std::size_t rj = lo; rj < hi; ++rj) out.emplace_back(q, rj - reference_first);
  }
  return out;
}

nlohmann::json evaluate_aligned(const AlignedSequences& sequences, const std::vector<Detection>& loops,
                                const std::vector<Detection>& ranked, ScoreOrder score_order) {
  const LoopGroundTruth truth = LoopGroundTruth::from_pairs(
      std::max(sequences.query_count, sequences.reference_count), sequences.pairs());
  nlohmann::json out = {
      {"available", true},
      {"truth",
       {{"aligned_tolerance_frames", sequences.tolerance_frames}, {"positives", truth.positive_count()}}}};
  out.update(loop_evaluation_json(loops, ranked, truth, score_order));
  return out;
}

}  // namespace loopgate
