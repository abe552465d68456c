#include "pipeline/methods/detection_method.hpp"

#include <spdlog/spdlog.h>

#include "core/error.hpp"
#include "pipeline/methods/method_registry.hpp"

namespace loopgate {

namespace {

// run.mode odometry: sync, decode, odometry only.
class NoDetection final : public DetectionMethod {
 public:
  explicit NoDetection(const PipelineConfig& config) : mode_(enum_name(config.run.mode)) {}
  std::string name() const override { return "dird"; }
  std::string mode() const override { return mode_; }
  bool detects() const override { return false; }

 private:
  std::string mode_;
};

}  // namespace

std::unique_ptr<DetectionMethod> make_no_detection(const MethodContext& context) {
  return std::make_unique<NoDetection>(context.config);
}

std::unique_ptr<DetectionMethod> make_detection_method(const MethodContext& context, bool dataset_has_images,
                                                       const std::filesystem::path& dataset_root) {
  validate_method(context.config);
  const RunConfig& run = context.config.run;
  if (run.seqslam()) {
    if (!dataset_has_images)
      throw DataError(dataset_root, "run.method seqslam needs images, and this dataset has none");
    if (run.mode == RunMode::kGated) {
      spdlog::info(
          "run: SeqSLAM gated (run.mode gated): only inside the pose gate's candidate areas, the frames "
          "their cells and sequences need; matches at the end of the stream");
    } else {
      spdlog::info(
          "run: SeqSLAM full (run.mode full): every frame, the whole difference matrix; matches at the "
          "end of the stream");
    }
    return method_entry(context.config)->make(context);
  }
  if (!run.detects_loops()) return make_no_detection(context);
  if (!dataset_has_images) {
    throw DataError(dataset_root, "run.mode " + std::string(enum_name(run.mode)) +
                                      " needs images, and this dataset has none (use --mode odometry)");
  }
  const PipelineConfig& config = context.config;
  if (config.standardize.mode == StandardizeMode::kBatch) {
    throw ConfigError(
        "standardize.mode: 'batch' needs the whole sequence before the first comparison (two-sequence runs); "
        "a single sequence streams: use 'causal'");
  }
  if (config.scale.online() && run.mode == RunMode::kGated) {
    throw ConfigError(
        "scale.mode: 'online' estimates the scale from the distances computed, assuming few of them are "
        "revisits; the gate computes them where revisits are likely, so it needs run.mode full (gated runs: "
        "standardize.mode causal with the fixed standardised scale)");
  }
  if (run.dird_seqslam()) {
    const DirdSeqSlamConfig& d = config.dird_seqslam;
    if (d.standardize == StandardizeMode::kBatch) {
      throw ConfigError(
          "dird_seqslam.standardize: 'batch' needs the whole sequence before the first comparison "
          "(two-sequence runs); a single sequence streams: use 'causal'");
    }
    spdlog::info(
        "run: dird-seqslam {} (DIRD {} normalisation, {} resize, {} standardisation): contrast over {} "
        "references, sequences of {} frames at {} velocities; a frame's verdict {} frames after its row",
        enum_name(run.mode), enum_name(d.normalization), enum_name(d.resize), enum_name(d.standardize),
        2 * d.search.contrast_half_window_frames + 1, config.match.sequence_length,
        d.search.velocities().size(), config.match.sequence_length - 1);
    return method_entry(config)->make(context);
  }
  if (config.standardize.enabled() || config.scale.online()) {
    spdlog::info("run: DIRD with standardize.mode {} ({}), scale.mode {}", enum_name(config.standardize.mode),
                 enum_name(config.standardize.distance), enum_name(config.scale.mode));
    // The standardised object also holds the online scale, for raw descriptors too.
    if (!config.standardize.enabled())
      return find_method_entry("dird", enum_name(run.mode), "causal")->make(context);
  }
  return method_entry(config)->make(context);
}

}  // namespace loopgate
