// summary.json of a single-sequence run, and its "evaluation" block: the detections against the dataset's
// ground truth (eval/run_evaluation.hpp), writing ground_truth.tum and truth_loops.csv for the plots.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "eval/loop_files.hpp"
#include "pipeline/methods/detection_method.hpp"
#include "pipeline/outputs/run_counters.hpp"
#include "pipeline/outputs/run_result.hpp"
#include "pipeline/outputs/time_accounting.hpp"
#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

class Dataset;
class ImageSource;
class ImuSynchronizer;
class LoopsWriter;
class LoopCloser;
class RunOutputs;

struct RunParts {
  const PipelineConfig& config;
  const Dataset& dataset;
  std::size_t first_frame = 0, last_frame = 0;
  const DetectionMethod& method;
  const RunOutputs& outputs;
  const LoopsWriter& loops;
  const ImageSource& images;
  const ImuSynchronizer* synchronizer = nullptr;
  const SeqIndex& seqs;
  double end_of_stream_ms = 0;
  // The evaluation's frames are [first_frame, evaluated_end_frame): those the run got to (an interrupted
  // run's are fewer than [first_frame, last_frame)); nullopt = last_frame.
  std::optional<std::size_t> evaluated_end_frame;
  const LoopCloser* closer = nullptr;
  EndOfStreamTime end_of_stream_time;  // the end of the stream's CPU time (time accounting)
  // eval.truth_pairs_file, read when the run was built (frame numbers as frames.csv shows them); null: the
  // truth comes from the ground-truth positions.
  const TruthPairs* truth_pairs = nullptr;
};

// The dataset world's ground plane ("xy", "xz" or "yz"): normal to its up axis, from the IMU and the ground
// truth when it has an IMU, -y for KITTI's camera world, else the axis nearest the normal of the positions'
// best-fit plane; "xy" when nothing tells.
CoordinatePlane horizontal_plane(const Dataset& dataset, const std::vector<Eigen::Vector3d>& p_w);

// eval.truth_pairs_file read and checked against the dataset's frame numbers (DataError naming the file and
// line), before the run starts; nullopt when the key is empty.
std::optional<TruthPairs> load_truth_pairs(const EvalConfig& eval, const Dataset& dataset);

// Evaluation block (docs/evaluation.md): {"available": false} without ground truth (positions or pairs) or
// for a method that does not detect loops; else positives from positions (r_true, gap, plane) or the listed
// pairs, the loops and the ranked detections scored (within r_accept, or listed), the PR curve, and for gated
// methods the gate coverage. Writes ground_truth.tum (with ground-truth poses) and truth_loops.csv into
// `out_dir`. Only frames the run processed take part.
// `truth_loops`, when given, receives the ground-truth pairs truth_loops.csv lists, as dataset frame indices
// (query i, reference j; the loop oracle's input).
nlohmann::json evaluate_run(const RunParts& parts, const std::filesystem::path& out_dir,
                            std::vector<std::pair<std::size_t, std::size_t>>* truth_loops = nullptr);

nlohmann::json make_run_summary(const RunParts& parts, const RunResult& result, nlohmann::json evaluation);

// summary.json "odometry_start": how a source that starts from the data started (initialiser, frame, time,
// the state it estimated, the decision's numbers) or why it did not, and the share of frames it tracked.
nlohmann::json odometry_start_json(const OdometryStart& start);

}  // namespace loopgate
