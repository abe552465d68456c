#include "eval/precision_recall.hpp"

#include <algorithm>
#include <map>

namespace loopgate {

namespace {
constexpr double kPrecision100 = 1.0;
constexpr double kPrecision99 = 0.99;
constexpr double kPrecision95 = 0.95;
}  // namespace

std::vector<Detection> best_detection_per_query(const std::vector<Detection>& detections,
                                                bool lower_is_better) {
  std::map<std::size_t, Detection> best;
  for (const Detection& d : detections) {
    const auto it = best.find(d.query);
    if (it == best.end()) {
      best.emplace(d.query, d);
    } else if (lower_is_better ? d.score < it->second.score : d.score > it->second.score) {
      it->second = d;
    }
  }
  std::vector<Detection> out;
  out.reserve(best.size());
  for (const auto& [query, d] : best) out.push_back(d);
  return out;
}

std::vector<Detection> judged_detections(const std::vector<Detection>& detections,
                                         const LoopGroundTruth& ground_truth) {
  std::vector<Detection> out;
  out.reserve(detections.size());
  for (const Detection& d : detections)
    if (!ground_truth.is_same_place_without_travel(d.query, d.reference)) out.push_back(d);
  return out;
}

PrResult evaluate_precision_recall(const std::vector<Detection>& detections,
                                   const LoopGroundTruth& ground_truth, const PrConfig& config) {
  const bool lower = config.lower_is_better();
  const std::vector<Detection> judged = judged_detections(detections, ground_truth);
  std::vector<Detection> best = best_detection_per_query(judged, lower);
  std::stable_sort(best.begin(), best.end(), [lower](const Detection& a, const Detection& b) {
    return lower ? a.score < b.score : a.score > b.score;
  });
  PrResult result;
  result.positives = ground_truth.positive_count();
  result.queries_with_detection = best.size();
  result.not_judged = detections.size() - judged.size();
  std::size_t accepted = 0, tp = 0, recalled = 0;
  for (std::size_t i = 0; i < best.size(); ++i) {
    const Detection& d = best[i];
    ++accepted;
    if (ground_truth.is_true_match(d.query, d.reference)) {
      ++tp;
      if (ground_truth.is_positive(d.query)) ++recalled;
    }
    // Equal scores are accepted together: emit a point after the last of a run of ties.
    if (i + 1 < best.size() && best[i + 1].score == d.score) continue;
    PrPoint p;
    p.threshold = d.score;
    p.detections = accepted;
    p.true_positives = tp;
    p.recalled = recalled;
    p.precision = static_cast<double>(tp) / static_cast<double>(accepted);
    p.recall =
        result.positives == 0 ? 0.0 : static_cast<double>(recalled) / static_cast<double>(result.positives);
    result.curve.push_back(p);
  }
  result.average_precision = average_precision(result.curve);
  result.recall_at_100 = recall_at_precision(result.curve, kPrecision100);
  result.recall_at_99 = recall_at_precision(result.curve, kPrecision99);
  result.recall_at_95 = recall_at_precision(result.curve, kPrecision95);
  return result;
}

double average_precision(const std::vector<PrPoint>& curve) {
  double area = 0.0;
  double previous_recall = 0.0;
  for (const PrPoint& p : curve) {
    area += (p.recall - previous_recall) * p.precision;
    previous_recall = p.recall;
  }
  return area;
}

double recall_at_precision(const std::vector<PrPoint>& curve, double min_precision) {
  double best = 0.0;
  for (const PrPoint& p : curve) {
    if (p.precision >= min_precision) best = std::max(best, p.recall);
  }
  return best;
}

}  // namespace loopgate
