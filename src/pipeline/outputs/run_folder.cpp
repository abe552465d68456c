#include "pipeline/outputs/run_folder.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "io/file_guard.hpp"

namespace loopgate {

const std::vector<std::string>& run_output_file_names() {
  static const std::vector<std::string> names = {"frames.csv",          "loops.csv",
                                                 "trajectory.tum",      "timing.csv",
                                                 "summary.json",        "trace.json",
                                                 "ground_truth.tum",    "truth_loops.csv",
                                                 "candidate_areas.csv", "candidate_cells.csv",
                                                 "descriptors.csv",     "descriptor.csv",
                                                 "loop_edges.csv",      "trajectory_corrected.tum",
                                                 "pose_graph.g2o"};
  return names;
}

void refuse_previous_outputs(const std::filesystem::path& out_dir, const std::vector<std::string>& names,
                             bool force, const std::string& command) {
  if (force) return;
  std::vector<std::string> found;
  std::error_code ec;
  for (const std::string& name : names) {
    if (std::filesystem::exists(out_dir / name, ec)) found.push_back(name);
  }
  if (found.empty()) return;
  constexpr std::size_t kListed = 5;
  std::string list;
  for (std::size_t k = 0; k < std::min(found.size(), kListed); ++k) list += (k ? ", " : "") + found[k];
  if (found.size() > kListed) list += fmt::format(" and {} more", found.size() - kListed);
  throw ConfigError(fmt::format(
      "{}: --out {} already holds another run's outputs ({}): choose another folder, or pass --force to "
      "replace them (their files would otherwise mix with this run's)",
      command, out_dir.string(), list));
}

void refuse_outputs_over_inputs(const PipelineConfig& config, const std::filesystem::path& out_dir,
                                const std::vector<std::filesystem::path>& extra_inputs) {
  std::vector<NamedPath> inputs;
  if (config.odometry.source == OdometrySourceKind::kFile)
    inputs.push_back({"odometry.file", config.odometry.file});
  if (!config.eval.truth_pairs_file.empty())  // a previous run's truth_loops.csv is a pairs file
    inputs.push_back({"eval.truth_pairs_file", config.eval.truth_pairs_file});
  for (const auto& input : extra_inputs) inputs.push_back({"an input of this command", input});
  std::vector<NamedPath> outputs;
  for (const std::string& name : run_output_file_names()) outputs.push_back({"the output", out_dir / name});
  refuse_outputs_over_inputs(outputs, inputs);
}

}  // namespace loopgate
