// The short result a run prints on the console at its end (`run`, and one line per method in `compare`):
// frames and real-time factor, loops true/false, AP / R@1 / R@100P, ATE before and after loop correction,
// problems and the output folder. Read from the run's summary.json fields, so the console and the file agree.
#pragma once

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "app/summary_fields.hpp"

namespace loopgate::app {

// `decimals` digits of a number field at `path`, or `missing` when the field is absent or not a number.
inline std::string result_number(const nlohmann::json& summary, const std::vector<std::string>& path,
                                 int decimals, const std::string& missing = "n/a") {
  const nlohmann::json* v = find_path(summary, path);
  if (!v || !v->is_number()) return missing;
  if (v->is_number_integer() || v->is_number_unsigned()) return fmt::format("{}", v->get<long long>());
  return fmt::format("{:.{}f}", v->get<double>(), decimals);
}

// True when the run had ground truth for its loops (evaluation available with a truth section).
inline bool has_loop_truth(const nlohmann::json& summary) {
  const nlohmann::json* available = find_path(summary, {"evaluation", "available"});
  return available && available->is_boolean() && available->get<bool>() &&
         find_path(summary, {"evaluation", "loop_truth"}) != nullptr;
}

// "AP 0.955, R@1 0.955, R@100P 0.925"; each n/a when the run had no positive (undefined, not 0).
inline std::string precision_recall_text(const nlohmann::json& summary) {
  const nlohmann::json* positives = find_path(summary, {"evaluation", "precision_recall", "positives"});
  const bool defined = positives && positives->is_number() && positives->get<double>() > 0;
  const auto field = [&](const char* key) {
    return defined ? result_number(summary, {"evaluation", "precision_recall", key}, 3) : std::string("n/a");
  };
  std::string text = fmt::format("AP {}, R@1 {}, R@100P {}", field("average_precision"), field("recall_at_1"),
                                 field("recall_at_100"));
  if (!defined && positives) text += " (no true loop in the range)";
  return text;
}

// "0.275 m -> 0.210 m" (odometry -> corrected by the verified loops), or the odometry alone.
inline std::string ate_text(const nlohmann::json& summary) {
  const nlohmann::json* available = find_path(summary, {"trajectory_accuracy", "available"});
  if (!available || !available->is_boolean() || !available->get<bool>()) return "n/a (no ground-truth poses)";
  std::string text = "odometry " + result_number(summary, {"trajectory_accuracy", "rmse_m"}, 3) + " m";
  for (const std::vector<std::string>& path :
       {std::vector<std::string>{"trajectory_accuracy_corrected"},
        std::vector<std::string>{"loop_correction", "trajectory_accuracy_corrected"}}) {
    std::vector<std::string> rmse = path;
    rmse.push_back("rmse_m");
    if (find_path(summary, rmse)) return text + " -> corrected " + result_number(summary, rmse, 3) + " m";
  }
  return text + " (no loop correction: verify.enabled is false)";
}

// The result block of one run (at most 8 lines), each line without its newline.
inline std::vector<std::string> run_result_lines(const nlohmann::json& summary, const std::string& out_dir) {
  std::vector<std::string> lines;
  lines.push_back(fmt::format("result of {} {} on {}:", summary.value("method", std::string("?")),
                              summary.value("mode", std::string("?")),
                              find_path(summary, {"dataset", "root"})
                                  ? find_path(summary, {"dataset", "root"})->get<std::string>()
                                  : std::string("?")));
  lines.push_back(fmt::format("  frames     {} of {} processed in {} s, real-time factor {}",
                              result_number(summary, {"frames_processed"}, 0),
                              result_number(summary, {"frames_in"}, 0), result_number(summary, {"wall_s"}, 2),
                              result_number(summary, {"realtime_factor"}, 1)));
  const std::string loops = result_number(summary, {"loops"}, 0, "0");
  if (has_loop_truth(summary)) {
    lines.push_back(fmt::format("  loops      {}: {} true, {} false ({} query frames with a true loop)",
                                loops, result_number(summary, {"evaluation", "loop_truth", "loops_true"}, 0),
                                result_number(summary, {"evaluation", "loop_truth", "loops_false"}, 0),
                                result_number(summary, {"evaluation", "precision_recall", "positives"}, 0)));
    lines.push_back("  quality    " + precision_recall_text(summary));
  } else {
    lines.push_back(fmt::format("  loops      {} (no ground truth: not judged true or false)", loops));
  }
  lines.push_back("  ATE        " + ate_text(summary));
  std::vector<std::string> problems;
  if (const nlohmann::json* p = find_path(summary, {"problems"}); p && p->is_array())
    for (const auto& item : *p) problems.push_back(item.is_string() ? item.get<std::string>() : item.dump());
  if (const nlohmann::json* m = find_path(summary, {"outputs_missing"}); m && m->is_array() && !m->empty())
    problems.push_back("outputs missing: " + m->dump());
  if (summary.value("interrupted", false)) problems.push_back("interrupted before the end of the range");
  const std::size_t issues = summary.contains("data_issues")
                                 ? summary["data_issues"].value("dataset_issue_count", std::size_t{0}) +
                                       summary["data_issues"].value("frames_with_issues", std::size_t{0})
                                 : 0;
  if (issues > 0)
    problems.push_back(fmt::format("{} data problems (summary.json data_issues, frames.csv)", issues));
  lines.push_back("  problems   " + (problems.empty() ? std::string("none") : problems.front()));
  if (problems.size() > 1)
    lines.push_back(fmt::format("             and {} more (summary.json)", problems.size() - 1));
  lines.push_back("  outputs    " + out_dir +
                  " (summary.json holds every figure, config.yaml the configuration)");
  return lines;
}

// The method `compare` recommends among those that ran: gated dird-seqslam when it ran, else its full form,
// else the first method. The plots draw it (scripts/plot.py reads "recommended" from compare.json).
inline std::string recommended_method(const std::vector<std::string>& ran) {
  for (const char* preferred : {"dird-seqslam-gated", "dird-seqslam"})
    for (const std::string& m : ran)
      if (m == preferred) return m;
  return ran.empty() ? std::string() : ran.front();
}

// compare's result block: one line per method (loops true/false, AP, R@1, R@100P, ATE), the recommended one
// marked, then the problems and the output folder.
inline std::vector<std::string> compare_result_lines(const std::vector<std::string>& ran,
                                                     const std::map<std::string, nlohmann::json>& summaries,
                                                     const std::string& out_dir) {
  std::vector<std::string> lines;
  if (ran.empty()) return lines;
  const std::string recommended = recommended_method(ran);
  const nlohmann::json& first = summaries.at(ran.front());
  lines.push_back(fmt::format("result: {} frames, {} methods (* recommended: {})",
                              result_number(first, {"frames_processed"}, 0), ran.size(), recommended));
  std::size_t width = 0;
  for (const std::string& m : ran) width = std::max(width, m.size());
  std::vector<std::string> problems;
  for (const std::string& m : ran) {
    const nlohmann::json& s = summaries.at(m);
    std::string loops = "loops " + result_number(s, {"loops"}, 0, "0");
    if (has_loop_truth(s))
      loops += fmt::format(
          " ({} true, {} false), {}", result_number(s, {"evaluation", "loop_truth", "loops_true"}, 0),
          result_number(s, {"evaluation", "loop_truth", "loops_false"}, 0), precision_recall_text(s));
    const nlohmann::json* ate = find_path(s, {"trajectory_accuracy", "rmse_m"});
    std::string ate_part =
        ate ? ", ATE " + result_number(s, {"trajectory_accuracy", "rmse_m"}, 3) + " m" : "";
    if (find_path(s, {"loop_correction", "trajectory_accuracy_corrected", "rmse_m"}))
      ate_part +=
          " -> " + result_number(s, {"loop_correction", "trajectory_accuracy_corrected", "rmse_m"}, 3) + " m";
    lines.push_back(fmt::format("{} {:<{}}  {}{}", m == recommended ? "*" : " ", m, width, loops, ate_part));
    if (const nlohmann::json* p = find_path(s, {"problems"}); p && p->is_array())
      for (const auto& item : *p)
        problems.push_back(m + ": " + (item.is_string() ? item.get<std::string>() : item.dump()));
    if (s.value("failed", false) && !s.value("error", std::string()).empty())
      problems.push_back(m + ": " + s.value("error", std::string()));
  }
  lines.push_back(
      "  problems   " + (problems.empty() ? std::string("none") : problems.front()) +
      (problems.size() > 1 ? fmt::format(" and {} more (compare.json)", problems.size() - 1) : ""));
  lines.push_back("  outputs    " + out_dir + " (compare.json, plots/, one folder per method)");
  return lines;
}

}  // namespace loopgate::app
