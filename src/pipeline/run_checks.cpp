#include "pipeline/run_checks.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>

#include "io/dataset.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/pipeline_config.hpp"
#include "pipeline/run_counters.hpp"

namespace loopgate {

RunCheckInput run_check_input(const PipelineConfig& config, const Dataset& dataset, const RunCounters& c,
                              const std::string& odometry_source, bool detects) {
  RunCheckInput in;
  in.frames_processed = c.processed;
  in.odometry_source = odometry_source;
  in.odometry_expected = odometry_expectation(config.odometry, config.ekf, dataset);
  in.frames_with_pose = c.frames_with_pose;
  in.first_odometry_problem = c.first_odometry_problem;
  in.frames_needing_image = c.frames_needing_image;
  in.frames_decoded = c.decoded;
  in.first_image_error = c.first_image_error;
  in.dataset_root = dataset.root().string();
  in.detects = detects;
  in.method = enum_name(config.run.method);
  const bool seqslam = config.run.seqslam();
  in.margin_key = seqslam ? "seqslam.exclusion_margin_frames" : "match.margin";
  in.margin_frames = seqslam ? config.seqslam.exclusion_margin_frames : config.match.margin;
  return in;
}

std::vector<std::string> run_problems(const RunCheckInput& in) {
  std::vector<std::string> problems;
  if (in.frames_processed == 0) return problems;
  if (in.odometry_source != "none" && in.frames_with_pose == 0) {
    problems.push_back(fmt::format(
        "no odometry: none of the {} frames got a pose from odometry.source {}; expected {}{}",
        in.frames_processed, in.odometry_source, in.odometry_expected,
        in.first_odometry_problem.empty() ? "" : " (first frame: " + in.first_odometry_problem + ")"));
  }
  if (in.frames_needing_image > 0 && in.frames_decoded == 0) {
    problems.push_back(fmt::format(
        "no image: none of the {} frames whose pixels the run needed could be read from {}; expected 8-bit "
        "grey or colour images (PNG, JPEG, PGM) of one size{}",
        in.frames_needing_image, in.dataset_root,
        in.first_image_error.empty() ? "" : " (first: " + in.first_image_error + ")"));
  }
  if (in.detects && in.frames_processed <= static_cast<std::size_t>(std::max(0, in.margin_frames))) {
    problems.push_back(fmt::format(
        "no detection possible: the run has {} frames, and run.method {} compares a frame only with frames "
        "at "
        "least {} = {} frames before it; expected more than {} frames (a longer --frames range or sequence, "
        "or a smaller {})",
        in.frames_processed, in.method, in.margin_key, in.margin_frames, in.margin_frames, in.margin_key));
  }
  return problems;
}

}  // namespace loopgate
