// The checks that keep a run from failing silently: a run that went through every frame and
// produced nothing usable says so on the console and exits non-zero, with its outputs written (they show
// what happened frame by frame). The cases, each judged from what the run saw, not predicted:
//   - no odometry: an odometry source was configured and not one frame got a pose from it (a trajectory file
//     of another sequence, ground truth that misses the frames, a filter that never initialised);
//   - no image: frames needed their pixels and not one could be read;
//   - odometry not started / started late / too few frames tracked: a source that starts from the data (the
//     ekf) did not start within ekf.max_init_s seconds of data after the first frame, or tracked fewer than
//     ekf.min_tracked_share of the frames from its start on;
//   - no detection possible: a detecting run with no more frames than the margin a loop needs between query
//     and reference, so no pair could ever be compared.
// Plain data in, messages out: the pipeline fills the input after the drain.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

struct RunCheckInput {
  std::size_t frames_processed = 0;
  // Odometry: the source's name ("none" = appearance only, no poses expected), what it needed and did not
  // find (names the file: "poses in FILE within ... of the frame times"), frames with an estimated pose, and
  // the first frame's reason for having none (run_check_input fills odometry_expected only when no frame
  // got a pose: the only message that uses it).
  std::string odometry_source;
  std::string odometry_expected;
  std::size_t frames_with_pose = 0;
  std::string first_odometry_problem;
  // The start of a source that starts from the data (OdometrySource::start), and the limits it is held to.
  std::optional<OdometryStart> start;
  double max_init_s = 0;
  double min_tracked_share = 0;
  // Images: frames whose pixels the run needed in the decode stage, how many were read, the first error (it
  // names the file).
  std::size_t frames_needing_image = 0;
  std::size_t frames_decoded = 0;
  std::string first_image_error;
  std::string dataset_root;
  // Detection: whether the run detects loops, the method, and the separation a loop needs (the key and its
  // value, e.g. match.margin = 200).
  bool detects = false;
  std::string method;
  std::string margin_key;
  int margin_frames = 0;
};

struct PipelineConfig;
class Dataset;
struct RunCounters;

// The input as a finished run fills it: its configuration, dataset and counters, the odometry source's name
// and start, and whether its method detects loops.
RunCheckInput run_check_input(const PipelineConfig& config, const Dataset& dataset,
                              const RunCounters& counters, const std::string& odometry_source, bool detects,
                              std::optional<OdometryStart> start = std::nullopt);

// One message per failed check, each starting with what is missing ("no odometry: ...", "odometry started
// late: ...", "odometry tracked too few frames: ...", "no image: ...", "no detection possible: ..."); empty
// when the run produced what it was asked for.
std::vector<std::string> run_problems(const RunCheckInput& input);

}  // namespace loopgate
