#include "app/compare_report.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <functional>

#include "app/summary_fields.hpp"

namespace loopgate::app {

using nlohmann::json;

TimeParts time_parts(const json& summary) {
  TimeParts t;
  const json* a = summary.contains("time_accounting") ? &summary.at("time_accounting") : nullptr;
  if (a == nullptr) return t;
  t.decode_ms = a->value("decode_ms", 0.0);
  t.describe_ms = a->value("describe_ms", 0.0);
  t.match_ms = a->value("match_ms", 0.0);
  t.rest_ms = a->value("rest_ms", 0.0);
  t.total_ms = a->value("total_ms", 0.0);
  return t;
}
json time_parts_json(const TimeParts& t) {
  return {{"decode_ms", t.decode_ms},
          {"describe_ms", t.describe_ms},
          {"match_ms", t.match_ms},
          {"rest_ms", t.rest_ms},
          {"total_ms", t.total_ms}};
}

std::string number(const json& value, int decimals) {
  if (value.is_null()) return "-";
  if (value.is_number_integer() || value.is_number_unsigned()) return std::to_string(value.get<long long>());
  return fmt::format("{:.{}f}", value.get<double>(), decimals);
}

std::string table(const std::vector<std::string>& methods, const std::map<std::string, json>& summaries,
                  bool two_sequence) {
  struct Row {
    std::string label;
    std::function<std::string(const json&)> cell;
  };
  const auto at = [](std::vector<std::string> path, int decimals = 0) {
    return [path, decimals](const json& s) {
      const json* v = find_path(s, path);
      return v ? number(*v, decimals) : std::string("-");
    };
  };
  const auto ms = [](double (*part)(const TimeParts&)) {
    return [part](const json& s) { return fmt::format("{:.1f}", part(time_parts(s))); };
  };
  // Precision and recall are undefined (n/a, not 0) when the range holds no true loop.
  const auto pr = [&at](const char* key) {
    return [cell = at({"evaluation", "precision_recall", key}, 3)](const json& s) {
      const json* positives = find_path(s, {"evaluation", "precision_recall", "positives"});
      if (positives && positives->is_number() && positives->get<double>() <= 0) return std::string("n/a");
      return cell(s);
    };
  };
  const Row wall = {"wall time (s)", at({"wall_s"}, 2)};
  const Row rss = {"peak RSS (MiB)", at({"peak_rss_mb"}, 0)};
  const std::vector<Row> quality = {
      {"loops", at({"loops"})},
      {"loops true", at({"evaluation", "loop_truth", "loops_true"})},
      {"loops false", at({"evaluation", "loop_truth", "loops_false"})},
      {"loops without travel", at({"evaluation", "loop_truth", "loops_without_travel"})},
      {"positive query frames", at({"evaluation", "precision_recall", "positives"})},
      {"average precision", pr("average_precision")},
      {"recall at 1 (top match)", pr("recall_at_1")},
      {"recall at 100% precision", pr("recall_at_100")},
      {"recall at 99% precision", pr("recall_at_99")},
      {"recall at 95% precision", pr("recall_at_95")},
  };
  // With verify.enabled: the loop correction after each run (outside its timing).
  const bool corrected = std::any_of(methods.begin(), methods.end(), [&](const std::string& m) {
    return summaries.at(m).contains("loop_correction");
  });
  const std::vector<Row> correction = {
      {"loops verified (geometry)", at({"loop_correction", "loops_verified"})},
      {"ATE odometry (m)", at({"trajectory_accuracy", "rmse_m"}, 3)},
      {"ATE corrected (m)", at({"loop_correction", "trajectory_accuracy_corrected", "rmse_m"}, 3)},
      {"loop correction (ms)", at({"loop_correction", "ms"}, 0)},
  };
  std::vector<Row> rows;
  if (two_sequence) {
    rows = {wall,
            rss,
            {"images decoded", at({"images_decoded"})},
            {"similarities computed", at({"similarities_computed"})}};
  } else {
    rows = {
        wall,
        {"cpu time (s)", at({"cpu_s"}, 2)},
        {"real-time factor", at({"realtime_factor"}, 1)},
        {"time (ms, thread CPU):", [](const json&) { return std::string(); }},
        {"  decode", ms([](const TimeParts& t) { return t.decode_ms; })},
        {"  describe", ms([](const TimeParts& t) { return t.describe_ms; })},
        {"  match", ms([](const TimeParts& t) { return t.match_ms; })},
        {"  rest", ms([](const TimeParts& t) { return t.rest_ms; })},
        {"  total", ms([](const TimeParts& t) { return t.total_ms; })},
        {"  describe + match", ms([](const TimeParts& t) { return t.describe_and_match_ms(); })},
        {"  decode+describe+match", ms([](const TimeParts& t) { return t.with_decode_ms(); })},
        {"  of rest: odometry", at({"time_accounting", "stages_cpu_ms", "odometry"}, 1)},
        {"  of rest: gate", at({"time_accounting", "stages_cpu_ms", "gate"}, 1)},
        {"  of decode: in describe", at({"time_accounting", "decode_in_describe_ms"}, 1)},
        {"  of match: in describe", at({"time_accounting", "match_in_describe_ms"}, 1)},
        rss,
        {"images decoded", at({"images_decoded"})},
        {"descriptors computed", at({"descriptors_computed"})},
        {"similarities computed", at({"similarities_computed"})},
        {"candidate areas", at({"candidate_areas"})},
    };
  }
  rows.insert(rows.end(), quality.begin(), quality.end());
  if (corrected) rows.insert(rows.end(), correction.begin(), correction.end());
  // Columns as wide as the longest method name.
  std::size_t width = 12;
  for (const auto& m : methods) width = std::max(width, m.size());
  width += 2;
  std::string out = fmt::format("{:<26}", "");
  for (const auto& m : methods) out += fmt::format("{:>{}}", m, width);
  out += "\n";
  for (const Row& row : rows) {
    out += fmt::format("{:<26}", row.label);
    for (const auto& m : methods) out += fmt::format("{:>{}}", row.cell(summaries.at(m)), width);
    out += "\n";
  }
  return out;
}

// The full / gated ratios into `comparison` and their text.
std::string full_over_gated(const json& f, const json& g, json& comparison) {
  std::string ratios;
  const TimeParts ft = time_parts(f);
  const TimeParts gt = time_parts(g);
  const auto ratio = [](double a, double b) { return b > 0 ? a / b : 0.0; };
  comparison.update({
      {"full_over_gated_decode_time", ratio(ft.decode_ms, gt.decode_ms)},
      {"full_over_gated_describe_time", ratio(ft.describe_ms, gt.describe_ms)},
      {"full_over_gated_match_time", ratio(ft.match_ms, gt.match_ms)},
      {"full_over_gated_describe_and_match_time",
       ratio(ft.describe_and_match_ms(), gt.describe_and_match_ms())},
      {"full_over_gated_decode_describe_and_match_time", ratio(ft.with_decode_ms(), gt.with_decode_ms())},
      {"full_over_gated_total_time", ratio(ft.total_ms, gt.total_ms)},
      {"full_over_gated_wall_time", ratio(f.value("wall_s", 0.0), g.value("wall_s", 0.0))},
      {"full_over_gated_descriptors",
       ratio(f.value("descriptors_computed", 0.0), g.value("descriptors_computed", 0.0))},
      {"full_over_gated_similarities",
       ratio(f.value("similarities_computed", 0.0), g.value("similarities_computed", 0.0))},
      {"paper_ratio", kPaperFullMs / kPaperGatedMs},
      {"paper_ratio_compares_with", "full_over_gated_describe_and_match_time"},
  });
  if (const json* cov = find_path(g, {"evaluation", "gate_coverage", "covered_fraction"}))
    comparison["gated_true_loop_frames_in_candidate_areas"] = *cov;
  // The paper's ratio is over a drive with loops; over a range without a true loop the ratio says nothing
  // about the paper's.
  const json* positives = find_path(g, {"evaluation", "precision_recall", "positives"});
  const bool loops_in_range = !positives || !positives->is_number() || positives->get<double>() > 0;
  const std::string paper =
      loops_in_range
          ? fmt::format(
                ": the paper's {:.2f}x (KITTI 00, {:.1f} s -> {:.1f} s, its Fig. 8 \"total time of "
                "loop-closure detection\": feature extraction + similarity) compares with this one",
                kPaperFullMs / kPaperGatedMs, kPaperFullMs / 1000.0, kPaperGatedMs / 1000.0)
          : std::string(" (no true loop in the range: not comparable with the paper's ratio)");
  if (!loops_in_range) comparison.erase("paper_ratio_compares_with");
  ratios = fmt::format(
      "full / gated, thread CPU time: decode {:.2f}x, describe {:.2f}x, match {:.2f}x, total {:.2f}x\n"
      "  describe + match {:.2f}x{}\n"
      "  decode + describe + match {:.2f}x (the paper does not say whether its time includes reading the "
      "images); wall {:.2f}x; descriptors {:.2f}x, similarities {:.1f}x\n",
      ratio(ft.decode_ms, gt.decode_ms), ratio(ft.describe_ms, gt.describe_ms),
      ratio(ft.match_ms, gt.match_ms), ratio(ft.total_ms, gt.total_ms),
      ratio(ft.describe_and_match_ms(), gt.describe_and_match_ms()), paper,
      ratio(ft.with_decode_ms(), gt.with_decode_ms()), comparison["full_over_gated_wall_time"].get<double>(),
      comparison["full_over_gated_descriptors"].get<double>(),
      comparison["full_over_gated_similarities"].get<double>());
  if (comparison.contains("gated_true_loop_frames_in_candidate_areas")) {
    const json& cov = g.at("evaluation").at("gate_coverage");
    ratios += fmt::format("true-loop query frames inside candidate areas: {} of {} ({:.1f}%)\n",
                          cov.at("covered_query_frames").get<std::size_t>(),
                          cov.at("positive_query_frames").get<std::size_t>(),
                          100.0 * cov.at("covered_fraction").get<double>());
  }
  return ratios;
}

std::string truth_counts_text(const json& summary, json& compare) {
  if (const json* truth = find_path(summary, {"evaluation", "truth"});
      truth && truth->contains("positives_3d")) {
    compare["truth_counts"] = {{"plane", truth->at("plane")},
                               {"positives", truth->at("positives")},
                               {"positives_3d", truth->at("positives_3d")},
                               {"horizontal_plane", truth->at("horizontal_plane")},
                               {"positives_horizontal", truth->at("positives_horizontal")},
                               {"min_travel_m", truth->at("min_travel_m")},
                               {"positives_without_min_travel", truth->at("positives_without_min_travel")}};
    return fmt::format(
        "ground-truth loop query frames: {} in 3-D, {} horizontal ({}); {} in the evaluation's plane ({}), "
        "{} before eval.min_travel_m = {} m took out revisits without travel\n",
        number(truth->at("positives_3d")), number(truth->at("positives_horizontal")),
        truth->at("horizontal_plane").get<std::string>(), number(truth->at("positives")),
        truth->at("plane").get<std::string>(), number(truth->at("positives_without_min_travel")),
        number(truth->at("min_travel_m"), 1));
  }
  return std::string();
}

std::string compare_header(const std::string& dataset, const json& summary) {
  std::string header =
      fmt::format("compare on {} ({} frames)", dataset, summary.value("frames_processed", 0));
  if (const json* truth = find_path(summary, {"evaluation", "truth"})) {
    if (truth->contains("pairs_file")) {
      header += fmt::format("; ground-truth loops: the {} pairs of {} ({} in the run's frames)",
                            number(truth->at("pairs")), truth->at("pairs_file").get<std::string>(),
                            number(truth->at("pairs_in_run")));
    } else {
      header += fmt::format(
          "; ground-truth loops within {} m ({}), gap {} frames, {} m of travel, detections true "
          "within {} m",
          number(truth->at("radius_m"), 2), truth->at("plane").get<std::string>(),
          number(truth->at("gap_frames")), number(truth->value("min_travel_m", json(0.0)), 1),
          number(truth->at("accept_radius_m"), 2));
    }
  }
  return header;
}

}  // namespace loopgate::app
