// The `ekf` odometry source (vio-ekf.md): the MSCKF of src/stages/ekf (VioEkf) behind the OdometrySource
// interface. Per frame it takes the decoded grey image and the IMU samples the sync node delivered since
// the previous frame; it reports the filter status (initialising / tracking / lost with the reason), the
// number of tracked features and the position sigma. It never throws for a bad frame: a missing or bad
// image, or a filter failure (e.g. NaN IMU readings), gives status lost. After a filter failure the filter
// re-initialises; after a frame without a usable image its IMU samples are kept and handed to the filter
// with the next frame, so the propagation has no hole.
#pragma once

#include <memory>
#include <optional>
#include <vector>

#include "core/types.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/vio_ekf.hpp"
#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

class EkfOdometry : public OdometrySource {
 public:
  // `ground_truth`: the dataset's ground-truth states, used only when config.init_mode is ground_truth
  // (interpolated to the frame time with ground_truth_state_at). `up_w`: the dataset world's up axis; the
  // filter runs in a world rotated so that it is +z (its gravity is along -z) and the poses are rotated
  // back. Throws ConfigError for an invalid config or camera calibration, or for init_mode ground_truth
  // without ground truth.
  EkfOdometry(const EkfConfig& config, const CameraCalibration& camera, const ImuCalibration& imu,
              std::vector<GroundTruthState> ground_truth,
              const Eigen::Vector3d& up_w = Eigen::Vector3d::UnitZ());

  const char* name() const override { return "ekf"; }
  bool needs_images() const override { return true; }
  bool needs_imu() const override { return true; }
  OdometryOutput process(const OdometryInput& input) override;
  // The tracker's image pyramid (VioEkf::prepare_image); nullptr for an image it cannot take.
  std::shared_ptr<const PreparedImage> prepare(const cv::Mat& image) const override;
  std::optional<OdometryStart> start() const override { return start_; }

  const VioEkf& filter() const { return ekf_; }
  // The last frame's full filter output (timings, update statistics), for tests and benchmarks.
  const std::optional<EkfFrameOutput>& last_output() const { return last_; }

 private:
  OdometryOutput lost(const OdometryInput& input, const std::string& reason);
  OdometryOutput track(const OdometryInput& input);

  EkfConfig config_;
  VioEkf ekf_;
  std::vector<GroundTruthState> ground_truth_;  // in the filter world
  Eigen::Matrix3d R_f_w_;                       // dataset world -> filter world (up -> +z)
  std::optional<EkfFrameOutput> last_;
  std::optional<PoseEstimate> last_pose_;
  std::vector<ImuSample> pending_imu_;  // samples of frames that did not reach the filter
  OdometryStart start_;
  std::optional<Timestamp> first_t_ns_;
  bool warned_late_ = false;
  void count(const OdometryInput& input, const OdometryOutput& out);
};

}  // namespace loopgate
