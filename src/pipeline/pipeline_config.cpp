#include "pipeline/pipeline_config.hpp"

#include <charconv>
#include <cmath>
#include <limits>

#include "core/error.hpp"
#include "io/config.hpp"

namespace loopgate {

namespace {

// Replay rates beyond these make no sense (a thousandth of real time; a million times real time is as fast
// as the graph drains), and (t - t_first) / R must stay far inside int64 ns.
constexpr double kMinRate = 1e-3;
constexpr double kMaxRate = 1e6;

std::optional<std::size_t> parse_index(const std::string& text, const std::string& frames) {
  if (text.empty()) return std::nullopt;
  std::size_t value = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc{} || ptr != text.data() + text.size()) {
    throw ConfigError("run.frames: '" + frames +
                      "' is not A:B with frame indices A < B (A or B may be omitted)");
  }
  return value;
}

}  // namespace

std::optional<double> RunConfig::rate_factor() const {
  if (rate == "max") return std::nullopt;
  double value = 0;
  const auto [ptr, ec] = std::from_chars(rate.data(), rate.data() + rate.size(), value);
  if (rate.empty() || ec != std::errc{} || ptr != rate.data() + rate.size() || !std::isfinite(value) ||
      !(value > 0)) {
    throw ConfigError("run.rate: " + quote_excerpt(rate) + " is not 'max' or a positive number");
  }
  if (value < kMinRate || value > kMaxRate) {
    throw ConfigError("run.rate: " + quote_excerpt(rate) + " is out of range: 'max' or a rate in [0.001, " +
                      "1000000] times real time");
  }
  return value;
}

std::pair<std::size_t, std::size_t> RunConfig::frame_range(std::size_t frame_count) const {
  std::size_t first = 0;
  std::size_t last = frame_count;
  if (!frames.empty()) {
    const auto colon = frames.find(':');
    if (colon == std::string::npos) {
      throw ConfigError("run.frames: " + quote_excerpt(frames) +
                        " is not A:B with frame indices A < B (A or B may be omitted)");
    }
    const auto a = parse_index(frames.substr(0, colon), frames);
    const auto b = parse_index(frames.substr(colon + 1), frames);
    if (a && b && *a >= *b) {
      throw ConfigError("run.frames: " + quote_excerpt(frames) + " is empty: A (" + std::to_string(*a) +
                        ") must be below B (" + std::to_string(*b) + "); B is exclusive");
    }
    if (a) first = *a;
    if (b) last = std::min(*b, frame_count);
  }
  if (first >= frame_count) {
    throw ConfigError("run.frames: " + quote_excerpt(frames) + " starts at frame " + std::to_string(first) +
                      ", and the dataset has " + std::to_string(frame_count) + " frames (0.." +
                      std::to_string(frame_count == 0 ? 0 : frame_count - 1) + ")");
  }
  if (first >= last) {
    throw ConfigError("run.frames: " + quote_excerpt(frames) + " selects no frame of the " +
                      std::to_string(frame_count) + " in the dataset");
  }
  return {first, last};
}

void DatasetConfig::validate() const {
  require(!bag_image_topic.empty(), "dataset.bag_image_topic",
          "the topic of a bag's images (EuRoC: /cam0/image_raw)", "''");
}

OpenOptions PipelineConfig::open_options() const {
  OpenOptions options;
  options.strict = run.strict;
  options.camera_index = run.camera_index;
  options.bag_image_topic = dataset.bag_image_topic;
  options.bag_imu_topic = dataset.bag_imu_topic;
  options.bag_asl_dir = dataset.bag_asl_dir;
  options.calibration_file = dataset.calibration;
  return options;
}

void RunConfig::validate() const {
  if (method != Detector::kDird && mode == RunMode::kOdometry) {
    throw ConfigError("run.method: " + std::string(enum_name(method)) +
                      " detects loops; it needs run.mode gated or full, not odometry");
  }
  rate_factor();
  require(threads >= 1 && threads <= 256, "run.threads", "in 1..256", std::to_string(threads));
  require_in("run.max_in_flight", max_in_flight, 1, 1024, "frames");
  require(camera_index >= 0 && camera_index <= 3, "run.camera_index",
          "0..3 (0, 1: EuRoC cam0/cam1, KITTI image_0/image_1; 2, 3: KITTI colour image_2/image_3)",
          std::to_string(camera_index));
  require_in("run.deadline_ms", deadline_ms, 0.0, 3.6e6, "ms (0 = the frame period)");
  require_in("run.image_cache_frames", image_cache_frames, 0, 100'000, "images");
  // The form of A:B and A < B (the dataset's size is checked when the run opens it).
  if (!frames.empty()) frame_range(std::numeric_limits<std::size_t>::max());
}

void PipelineConfig::validate_odometry_none() const {
  if (odometry.source != OdometrySourceKind::kNone) return;
  if (run.mode == RunMode::kGated) {
    throw ConfigError(
        "run.mode: 'gated' needs poses for the pose gate, and odometry.source is none (appearance only): use "
        "run.mode full (--mode full), or an odometry source");
  }
  if (run.mode == RunMode::kOdometry) {
    throw ConfigError(
        "run.mode: 'odometry' estimates poses only, and odometry.source is none: nothing to do");
  }
  if (verify.enabled) {
    throw ConfigError(
        "verify.enabled: geometric verification triangulates with the odometry poses, and odometry.source is "
        "none: set verify.enabled=false");
  }
}

void PipelineConfig::validate_gate_feedback() const {
  if (!gate.feedback) return;
  if (!verify.enabled) {
    throw ConfigError(
        "gate.feedback: the gate is re-anchored on verified loop closures, and verify.enabled is false: set "
        "verify.enabled=true or gate.feedback=false");
  }
}

void DirdSeqSlamConfig::validate() const {
  codes.validate();
  if (codes.compact() && standardize == StandardizeMode::kOff) {
    throw ConfigError("dird_seqslam.code: '" + std::string(enum_name(codes.code)) +
                      "' codes the standardised descriptor: needs dird_seqslam.standardize causal or batch");
  }
  search.validate();
  viewpoint.validate();
  if (viewpoint.enabled() && codes.compact()) {
    throw ConfigError(
        "dird_seqslam.viewpoint_lateral_m: the viewpoint tolerance compares int8 codes; it needs "
        "dird_seqslam.code int8 (it is '" +
        std::string(enum_name(codes.code)) + "')");
  }
}

void EvalConfig::validate() const {
  require(std::isfinite(truth_radius_m) && truth_radius_m > 0 && truth_radius_m <= 1e4, "eval.truth_radius_m",
          "in (0, 10000] m", std::to_string(truth_radius_m));
  require_in("eval.truth_gap_frames", truth_gap_frames, 0, 1'000'000, "frames");
  require_in("eval.accept_radius_m", accept_radius_m, 0.0, 1e4, "m (0 = eval.truth_radius_m)");
  revisit.validate("eval.min_travel_m");
  require_in("eval.aligned_tolerance_frames", aligned_tolerance_frames, -1, 1'000'000,
             "frames (-1 = not aligned)");
}

void OutputConfig::validate() const {
  require_in("output.flush_every", flush_every, 1, 1'000'000, "frames");
}

}  // namespace loopgate
