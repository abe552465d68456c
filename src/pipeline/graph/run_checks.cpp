#include "pipeline/graph/run_checks.hpp"

#include <spdlog/fmt/fmt.h>

#include <algorithm>
#include <utility>

#include "io/dataset.hpp"
#include "pipeline/methods/method_registry.hpp"
#include "pipeline/odometry_factory.hpp"
#include "pipeline/outputs/run_counters.hpp"
#include "pipeline/pipeline_config.hpp"

namespace loopgate {

RunCheckInput run_check_input(const PipelineConfig& config, const Dataset& dataset, const RunCounters& c,
                              const std::string& odometry_source, bool detects,
                              std::optional<OdometryStart> start) {
  RunCheckInput in;
  in.start = std::move(start);
  in.max_init_s = config.ekf.max_init_s;
  in.min_tracked_share = config.ekf.min_tracked_share;
  in.frames_processed = c.processed;
  in.odometry_source = odometry_source;
  in.frames_with_pose = c.frames_with_pose;
  // What the source needed: only for the message of a run where no frame got a pose (a file source reads
  // its whole trajectory again for it, as much memory as the run's odometry at its end).
  if (odometry_source != "none" && c.frames_with_pose == 0)
    in.odometry_expected = odometry_expectation(config.odometry, config.ekf, dataset);
  in.first_odometry_problem = c.first_odometry_problem;
  in.frames_needing_image = c.frames_needing_image;
  in.frames_decoded = c.decoded;
  in.first_image_error = c.first_image_error;
  in.dataset_root = dataset.root().string();
  in.detects = detects;
  in.method = enum_name(config.run.method);
  const MethodEntry* method = method_entry(config);
  const MarginKey margin = method != nullptr ? method->margin : MarginKey::kMatchMargin;
  in.margin_key = enum_name(margin);
  in.margin_frames =
      margin == MarginKey::kSeqSlamExclusion ? config.seqslam.exclusion_margin_frames : config.match.margin;
  return in;
}

std::vector<std::string> run_problems(const RunCheckInput& in) {
  std::vector<std::string> problems;
  if (in.frames_processed == 0) return problems;
  const OdometryStart* start = in.start ? &*in.start : nullptr;
  if (start != nullptr && start->frames_seen > 0 && !start->started) {
    // Never started: the initialisers' last word says why, with the numbers.
    problems.push_back(fmt::format(
        "no odometry: odometry.source {} never started: still initialising after {:.2f} s of data from the "
        "first frame ({} frames; ekf.max_init_s = {} s): {}",
        in.odometry_source, start->data_s, start->frames_seen, in.max_init_s, start->status));
  } else if (in.odometry_source != "none" && in.frames_with_pose == 0) {
    problems.push_back(fmt::format(
        "no odometry: none of the {} frames got a pose from odometry.source {}; expected {}{}",
        in.frames_processed, in.odometry_source, in.odometry_expected,
        in.first_odometry_problem.empty() ? "" : " (first frame: " + in.first_odometry_problem + ")"));
  }
  if (start != nullptr && start->started) {
    if (start->after_first_s > in.max_init_s) {
      problems.push_back(fmt::format(
          "odometry started late: odometry.source {} started ({} initialiser) at frame {}, {:.2f} s of data "
          "after the first frame; expected within ekf.max_init_s = {} s",
          in.odometry_source, start->method, start->frame, start->after_first_s, in.max_init_s));
    }
    const double share = start->frames_since_start > 0 ? static_cast<double>(start->frames_tracking) /
                                                             static_cast<double>(start->frames_since_start)
                                                       : 0.0;
    if (share < in.min_tracked_share) {
      problems.push_back(fmt::format(
          "odometry tracked too few frames: odometry.source {} tracked {} of the {} frames from its start on "
          "({:.1f}%; {} start(s)); expected at least ekf.min_tracked_share = {:.1f}%",
          in.odometry_source, start->frames_tracking, start->frames_since_start, 100.0 * share, start->starts,
          100.0 * in.min_tracked_share));
    }
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
        "at least {} = {} frames before it; expected more than {} frames (a longer --frames range or "
        "sequence, or a smaller {})",
        in.frames_processed, in.method, in.margin_key, in.margin_frames, in.margin_frames, in.margin_key));
  }
  return problems;
}

}  // namespace loopgate
