#include "pipeline/outputs/run_summary.hpp"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <limits>
#include <optional>
#include <utility>

#include "core/geometry.hpp"
#include "eval/run_evaluation.hpp"
#include "io/config.hpp"
#include "io/dataset.hpp"
#include "io/provenance.hpp"
#include "io/writers.hpp"
#include "pipeline/frame/frame_steps.hpp"
#include "pipeline/loops/loop_closer.hpp"
#include "pipeline/loops/loops_writer.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/outputs/run_metrics.hpp"
#include "pipeline/outputs/run_outputs.hpp"

namespace loopgate {

std::optional<TruthPairs> load_truth_pairs(const EvalConfig& eval, const Dataset& dataset) {
  if (eval.truth_pairs_file.empty()) return std::nullopt;
  const std::size_t numbers =
      dataset.frame_count() == 0 ? 0 : dataset.source_index(dataset.frame_count() - 1) + 1;
  TruthPairs pairs = read_truth_pairs(eval.truth_pairs_file, numbers);
  std::size_t queries = 0;
  for (std::size_t k = 0; k < pairs.pairs.size(); ++k)
    queries += (k == 0 || pairs.pairs[k].first != pairs.pairs[k - 1].first) ? 1 : 0;
  spdlog::info("eval: loop ground truth from {}: {} pairs over {} query frames (eval.truth_pairs_file)",
               eval.truth_pairs_file, pairs.pairs.size(), queries);
  if (pairs.pairs.empty()) {
    spdlog::warn("eval: {} lists no pair: every detection will count as false", eval.truth_pairs_file);
  }
  return pairs;
}

CoordinatePlane horizontal_plane(const Dataset& dataset, const std::vector<Eigen::Vector3d>& p_w) {
  std::optional<Eigen::Vector3d> up_w = world_up_axis_from_imu(dataset);
  if (!up_w && dataset.layout() == DatasetLayout::kKitti) up_w = Eigen::Vector3d(0.0, -1.0, 0.0);
  if (!up_w) {
    std::vector<Eigen::Vector3d> finite;
    for (const Eigen::Vector3d& p : p_w)
      if (p.allFinite()) finite.push_back(p);
    if (finite.size() >= 3) up_w = plane_normal(finite);
  }
  if (!up_w) return CoordinatePlane::kXy;
  const int axis = dominant_axis(*up_w);
  return axis == 0 ? CoordinatePlane::kYz : axis == 1 ? CoordinatePlane::kXz : CoordinatePlane::kXy;
}

namespace {

// The ground truth's plane of eval.plane: auto is x-z for the KITTI layout (its camera frame), 3-D otherwise.
CoordinatePlane truth_plane(TruthPlane plane, const Dataset& dataset) {
  switch (plane) {
    case TruthPlane::kXz: return CoordinatePlane::kXz;
    case TruthPlane::kXy: return CoordinatePlane::kXy;
    case TruthPlane::kXyz: return CoordinatePlane::kXyz;
    case TruthPlane::kAuto: break;
  }
  return dataset.layout() == DatasetLayout::kKitti ? CoordinatePlane::kXz : CoordinatePlane::kXyz;
}

// Truth from a file of pairs (eval.truth_pairs_file): frame numbers (as frames.csv shows them) -> indices
// within the `n` evaluated frames from `first`; pairs with a frame outside them (another --frames range, a
// rejected row) cannot be detected and are left out, counted.
void add_truth_pairs(const RunParts& parts, std::size_t first, std::size_t n,
                     SequenceEvaluationInput& input) {
  const Dataset& dataset = parts.dataset;
  std::vector<std::size_t> labels(n);
  for (std::size_t k = 0; k < n; ++k) labels[k] = dataset.source_index(first + k);
  const auto index_of = [&labels](std::size_t label) -> std::optional<std::size_t> {
    const auto it = std::lower_bound(labels.begin(), labels.end(), label);
    if (it == labels.end() || *it != label) return std::nullopt;
    return static_cast<std::size_t>(it - labels.begin());
  };
  // A pair closer than the method's margin is one the run never compares: as a positive it could never be
  // found, so it is left out too, counted and warned about.
  const bool seqslam = parts.config.run.seqslam();
  const char* margin_key = seqslam ? "seqslam.exclusion_margin_frames" : "match.margin";
  int margin_frames = seqslam ? parts.config.seqslam.exclusion_margin_frames : parts.config.match.margin;
  if (seqslam && parts.config.seqslam.exclusion == SeqSlamExclusionKind::kNone)
    margin_frames = 0;  // every pair is compared
  const auto margin = static_cast<std::size_t>(std::max(0, margin_frames));
  std::vector<std::pair<std::size_t, std::size_t>> used;
  std::size_t in_run = 0, too_close = 0;
  std::optional<std::pair<std::size_t, std::size_t>> first_too_close;
  for (const auto& [q, r] : parts.truth_pairs->pairs) {
    const auto qi = index_of(q);
    const auto ri = index_of(r);
    if (!qi || !ri) continue;
    ++in_run;
    if (*qi - *ri < margin) {
      ++too_close;
      if (!first_too_close) first_too_close = {q, r};
      continue;
    }
    used.emplace_back(*qi, *ri);
  }
  if (too_close > 0) {
    spdlog::warn(
        "eval: {} of the {} pairs of {} in the run are closer than {} = {} frames (first: query {}, "
        "reference {}): the run never compares such a pair, so they are left out of the evaluation",
        too_close, in_run, parts.config.eval.truth_pairs_file, margin_key, margin, first_too_close->first,
        first_too_close->second);
  }
  input.pairs_truth = {{"pairs_file", parts.config.eval.truth_pairs_file},
                       {"pairs_file_rows", parts.truth_pairs->rows},
                       {"pairs", parts.truth_pairs->pairs.size()},
                       {"pairs_in_run", in_run},
                       {"pairs_closer_than_margin", too_close},
                       {"margin_key", margin_key}};
  input.pairs = std::move(used);
  input.frame_count = n;
}

// How the truth depends on the rule (compare prints these): positives in 3-D and in the ground plane, and
// before eval.min_travel_m took out the revisits without travel (hovering, standing still).
void add_truth_rule_counts(const Dataset& dataset, const SequenceEvaluationInput& input,
                           nlohmann::json& truth_json) {
  const auto positives = [&](CoordinatePlane plane, double min_travel_m) {
    GroundTruthConfig truth = input.truth;
    truth.plane = plane;
    truth.revisit.min_travel_m = min_travel_m;
    return LoopGroundTruth::from_positions(input.p_w, truth).positive_count();
  };
  const CoordinatePlane horizontal = horizontal_plane(dataset, input.p_w);
  truth_json["positives_3d"] = positives(CoordinatePlane::kXyz, input.truth.revisit.min_travel_m);
  truth_json["horizontal_plane"] = std::string(enum_name(horizontal));
  truth_json["positives_horizontal"] = positives(horizontal, input.truth.revisit.min_travel_m);
  truth_json["positives_without_min_travel"] = positives(input.truth.plane, 0.0);
}

// The gate's coverage of the true loops: which of them the method's candidate areas held.
void add_gate_coverage(const RunParts& parts, const MethodEvaluation& method,
                       const SequenceEvaluationInput& input, SequenceEvaluation& evaluation,
                       std::size_t first, std::size_t n) {
  const std::size_t processed = parts.outputs.frames_through();
  std::vector<std::int64_t> seq_of_index(n, -1);
  for (std::size_t seq = 0; seq < processed; ++seq) {
    const std::size_t k = parts.seqs.frame(static_cast<std::int64_t>(seq)) - first;
    if (k < n) seq_of_index[k] = static_cast<std::int64_t>(seq);
  }
  const auto processed_frame = [&](std::size_t q) { return seq_of_index[q] >= 0; };
  const auto covered = [&](std::size_t q, std::size_t r) {
    return method.covers(seq_of_index[q], seq_of_index[r]);
  };
  evaluation.json["gate_coverage"] =
      input.pairs
          ? gate_coverage_json(evaluation.truth, parts.config.match.margin, processed_frame, covered)
          : gate_coverage_json(input.p_w, input.truth, parts.config.match.margin, processed_frame, covered);
}

}  // namespace

nlohmann::json evaluate_run(const RunParts& parts, const std::filesystem::path& out_dir,
                            std::vector<std::pair<std::size_t, std::size_t>>* truth_loops_out) {
  const Dataset& dataset = parts.dataset;
  if (!parts.method.detects() || (!dataset.has_ground_truth() && !parts.truth_pairs))
    return {{"available", false}};
  const std::size_t first = parts.first_frame;
  const std::size_t end = std::min(parts.evaluated_end_frame.value_or(parts.last_frame), parts.last_frame);
  const std::size_t n = end - std::min(end, first);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  SequenceEvaluationInput input;
  input.p_w.assign(n, Eigen::Vector3d::Constant(nan));
  if (dataset.has_ground_truth()) {
    TumWriter truth_tum(out_dir / "ground_truth.tum");
    for (std::size_t k = 0; k < n; ++k) {
      if (const auto T_w_b = dataset.ground_truth_T_w_b(first + k)) {
        input.p_w[k] = T_w_b->translation();
        truth_tum.write(dataset.frame_t_ns(first + k), *T_w_b);
      }
    }
    truth_tum.close();
  }
  if (parts.truth_pairs) add_truth_pairs(parts, first, n, input);
  const EvalConfig& eval = parts.config.eval;
  input.truth.radius_m = eval.truth_radius_m;
  input.truth.gap_frames = eval.truth_gap_frames;
  input.truth.plane = truth_plane(eval.plane, dataset);
  input.truth.accept_radius_m = eval.effective_accept_radius_m();
  input.truth.revisit = eval.revisit;
  const MethodEvaluation method = parts.method.evaluation();
  const auto within_range = [first](const std::vector<Detection>& detections) {
    std::vector<Detection> out;
    out.reserve(detections.size());
    for (const Detection& d : detections) out.push_back({d.query - first, d.reference - first, d.score});
    return out;
  };
  input.loops = within_range(parts.loops.loops());
  input.ranked = method.ranked ? within_range(*method.ranked) : input.loops;
  input.score_order = parts.method.score_order();
  SequenceEvaluation evaluation = evaluate_sequence(input);
  if (!input.pairs) add_truth_rule_counts(dataset, input, evaluation.json["truth"]);
  CsvWriter truth_loops(out_dir / "truth_loops.csv", {"i", "j"});
  for (const auto& [q, r] : evaluation.truth_pairs) {
    if (truth_loops_out) truth_loops_out->emplace_back(first + q, first + r);
    truth_loops.write_row(
        {std::to_string(dataset.source_index(first + q)), std::to_string(dataset.source_index(first + r))});
  }
  truth_loops.close();
  if (end < parts.last_frame) {  // the run stopped early: say over which frames it was evaluated
    evaluation.json["frames_evaluated"] = {{"first_frame", first},
                                           {"end_frame", end},
                                           {"requested_end_frame", parts.last_frame},
                                           {"why", "the run stopped before the end of the range"}};
  }

  if (method.covers) add_gate_coverage(parts, method, input, evaluation, first, n);
  return evaluation.json;
}

nlohmann::json make_run_summary(const RunParts& parts, const RunResult& result, nlohmann::json evaluation) {
  const Dataset& dataset = parts.dataset;
  const RunCounters& c = parts.outputs.counters();
  nlohmann::json issues = nlohmann::json::array();
  for (const auto& issue : dataset.issues()) {
    if (issues.size() >= RunCounters::kMaxListedProblems) break;
    issues.push_back(issue.to_string());
  }
  const std::size_t reads = parts.images.reads_for_description();
  nlohmann::json config_json = config_to_json(parts.config);
  nlohmann::json summary = {
      {"provenance", provenance_json(config_json)},
      {"config", std::move(config_json)},
      {"dataset",
       {{"root", dataset.root().string()},
        {"layout", std::string(enum_name(dataset.layout()))},
        {"frame_count", dataset.frame_count()},
        {"first_frame", parts.first_frame},
        {"last_frame", parts.last_frame},
        {"has_images", dataset.has_images()},
        {"has_imu", dataset.has_imu()},
        {"has_ground_truth", dataset.has_ground_truth()}}},
      {"frames_in", result.frames_in},
      {"frames_processed", result.frames_processed},
      {"frames_dropped", result.frames_dropped},
      {"deadline_misses", result.deadline_misses},
      {"wall_s", result.wall_s},
      {"data_s", result.data_s},
      {"realtime_factor", result.realtime_factor},
      {"throughput_fps",
       result.wall_s > 0 ? static_cast<double>(result.frames_processed) / result.wall_s : 0.0},
      {"cpu_s", result.cpu_s},
      {"cpu_wall_ratio", result.wall_s > 0 ? result.cpu_s / result.wall_s : 0.0},
      {"peak_rss_mb", result.peak_rss_mb},
      {"threads", parts.config.run.threads},
      {"interrupted", result.interrupted},
      {"failed", result.failed},
      {"error", result.error},
      {"counts",
       {{"frames_ok", result.frames_ok},
        {"frames_warning", result.frames_warning},
        {"frames_error", result.frames_error},
        {"decoded", c.decoded},
        {"odometry_lost", c.odometry_lost}}},
      {"mode", parts.method.mode()},
      {"method", parts.method.name()},
      {"score_order", std::string(enum_name(parts.method.score_order()))},
      {"end_of_stream_ms", parts.end_of_stream_ms},
      {"images_decoded", c.decoded + reads},
      {"images_read_for_description", reads},
      {"image_cache_hits", parts.images.cache_hits()},
      {"candidate_areas", 0},
      {"descriptors_computed", 0},
      {"similarities_computed", 0},
      {"loops", parts.loops.count()},
      {"evaluation", std::move(evaluation)},
      {"gate", {{"enabled", false}}},
      {"trajectory_accuracy", trajectory_accuracy_json(parts.outputs.tracked_poses(), dataset)},
      {"stages", parts.outputs.profiler().to_json()},
      {"time_accounting", time_accounting_json(parts.outputs.frame_times(), parts.end_of_stream_time)},
      {"data_issues",
       {{"dataset_issue_count", dataset.issues().size()},
        {"dataset_issues", issues},
        {"image_errors", c.image_errors},
        {"imu_gaps", c.imu_gaps},
        {"imu_out_of_order", c.imu_out_of_order},
        {"imu_duplicates", c.imu_duplicates},
        {"imu_missing_frames", c.imu_missing_frames},
        {"imu_anomalies_in_stream", parts.synchronizer ? parts.synchronizer->anomalies().size() : 0},
        {"frames_with_issues", c.problem_frame_count},
        {"frames", c.problem_frames}}},
  };
  nlohmann::json detection = c.outcomes_json();
  detection["nms_delay_frames"] = 0;
  nlohmann::json method = parts.method.summary();
  if (method.contains("detection")) {
    detection.update(method["detection"]);
    method.erase("detection");
  }
  summary["detection"] = std::move(detection);
  if (parts.closer && parts.closer->active())
    summary.update(parts.closer->summary_fields(parts.outputs.tracked_poses()));
  summary.update(method);
  return summary;
}

nlohmann::json odometry_start_json(const OdometryStart& start) {
  const auto vec = [](const Eigen::Vector3d& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); };
  nlohmann::json j = {{"started", start.started},
                      {"frames_seen", start.frames_seen},
                      {"data_s", start.data_s},
                      {"starts", start.starts}};
  if (!start.started) {
    j["status"] = start.status;
    return j;
  }
  j.update({{"method", start.method},
            {"frame", start.frame},
            {"t_s", ns_to_s(start.t_ns)},
            {"after_first_frame_s", start.after_first_s},
            {"frames_since_start", start.frames_since_start},
            {"frames_tracking", start.frames_tracking},
            {"tracked_share", start.frames_since_start > 0 ? static_cast<double>(start.frames_tracking) /
                                                                 static_cast<double>(start.frames_since_start)
                                                           : 0.0},
            {"state",
             {{"up_in_imu_frame", vec(start.up_i)},
              {"roll_deg", start.roll_deg},
              {"pitch_deg", start.pitch_deg},
              {"v_w_mps", vec(start.v_w_mps)},
              {"gyro_bias_radps", vec(start.gyro_bias_radps)},
              {"accel_bias_mps2", vec(start.accel_bias_mps2)},
              {"scale", start.scale}}},
            {"window_s", start.window_s},
            {"detail", start.detail}});
  return j;
}

}  // namespace loopgate
