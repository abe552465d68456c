#include "pipeline/pipeline_config.hpp"

#include <charconv>
#include <cmath>

#include "core/error.hpp"
#include "io/config.hpp"

namespace loopgate {

namespace {

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
    throw ConfigError("run.rate: '" + rate + "' is not 'max' or a positive number");
  }
  return value;
}

std::pair<std::size_t, std::size_t> RunConfig::frame_range(std::size_t frame_count) const {
  std::size_t first = 0;
  std::size_t last = frame_count;
  if (!frames.empty()) {
    const auto colon = frames.find(':');
    if (colon == std::string::npos) {
      throw ConfigError("run.frames: '" + frames +
                        "' is not A:B with frame indices A < B (A or B may be omitted)");
    }
    if (auto a = parse_index(frames.substr(0, colon), frames)) first = *a;
    if (auto b = parse_index(frames.substr(colon + 1), frames)) last = std::min(*b, frame_count);
  }
  if (first >= last) {
    throw ConfigError("run.frames: '" + frames + "' selects no frame of the " + std::to_string(frame_count) +
                      " in the dataset");
  }
  return {first, last};
}

void RunConfig::validate() const {
  if (method != Detector::kDird && mode == RunMode::kOdometry) {
    throw ConfigError("run.method: " + std::string(enum_name(method)) +
                      " detects loops; it needs run.mode gated or full, not odometry");
  }
  rate_factor();
  require(threads >= 1 && threads <= 256, "run.threads", "in 1..256", std::to_string(threads));
  require(max_in_flight >= 1, "run.max_in_flight", ">= 1", std::to_string(max_in_flight));
  require(camera_index == 0 || camera_index == 1, "run.camera_index", "0 or 1", std::to_string(camera_index));
  require(deadline_ms >= 0, "run.deadline_ms", ">= 0", std::to_string(deadline_ms));
  require(image_cache_frames >= 0, "run.image_cache_frames", ">= 0", std::to_string(image_cache_frames));
  if (!frames.empty()) frame_range(static_cast<std::size_t>(-1));
}

void DirdSeqSlamConfig::validate() const {
  require_one_of("dird_seqslam.normalization", normalization, {"libdird", "l2"});
  require_one_of("dird_seqslam.resize", resize, {"nearest", "area"});
  require_one_of("dird_seqslam.standardize", standardize, {"off", "causal", "batch"});
  search.validate();
}

void EvalConfig::validate() const {
  require(std::isfinite(truth_radius_m) && truth_radius_m > 0, "eval.truth_radius_m", "> 0",
          std::to_string(truth_radius_m));
  require(truth_gap_frames >= 0, "eval.truth_gap_frames", ">= 0", std::to_string(truth_gap_frames));
  require_one_of("eval.plane", plane, {"auto", "xz", "xy", "xyz"});
  require(std::isfinite(accept_radius_m) && accept_radius_m >= 0, "eval.accept_radius_m",
          ">= 0 (0 = eval.truth_radius_m)", std::to_string(accept_radius_m));
  require(aligned_tolerance_frames >= -1, "eval.aligned_tolerance_frames", ">= 0, or -1 (not aligned)",
          std::to_string(aligned_tolerance_frames));
}

void OutputConfig::validate() const {
  require_one_of("output.progress", progress, {"auto", "on", "off"});
  require(flush_every >= 1, "output.flush_every", ">= 1", std::to_string(flush_every));
}

}  // namespace loopgate
