// Odometry sources (vio-ekf.md § Odometry sources): one interface, chosen by `odometry.source`.
//   drift: ground truth corrupted by a seeded random walk in position, heading and scale, with the
//          covariance of that drift model (for datasets without IMU and controlled experiments);
//   file:  an external TUM trajectory, covariance from the growth model sigma^2 = a + b * distance.
// (The `ekf` source comes with its own issue.) Every source emits one PoseEstimate per image.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/types.hpp"

namespace cv {
class Mat;
}

namespace loopgate {

class Dataset;

struct OdometryConfig {
  std::string source = "drift";  // drift | file
  std::int64_t seed = 1;
  // drift: random walks driven by the distance travelled (per sqrt of metres).
  double drift_position_sigma_m_per_sqrt_m = 0.005;
  double drift_heading_sigma_rad_per_sqrt_m = 0.0003;
  double drift_scale_sigma_per_sqrt_m = 0.0005;
  // Axis of the heading drift in the world frame: x | y | z | auto (normal of the best-fit plane of the
  // ground-truth positions, e.g. -y for KITTI camera frames, z for EuRoC).
  std::string heading_axis = "auto";
  double initial_sigma_m = 0.01;     // floor added to the position variances
  double initial_sigma_rad = 0.001;  // floor added to the rotation variances
  // file: TUM trajectory (relative paths are relative to the working directory).
  std::string file;
  double file_sigma2_a_m2 = 0.01;
  double file_sigma2_b_m2_per_m = 0.01;
  double file_rot_sigma2_a_rad2 = 1e-4;
  double file_rot_sigma2_b_rad2_per_m = 1e-5;
  double file_max_gap_s = 0.5;  // a frame farther than this from any trajectory pose is reported lost

  template <class V>
  void visit(V&& v) {
    v("source", source);
    v("seed", seed);
    v("drift_position_sigma_m_per_sqrt_m", drift_position_sigma_m_per_sqrt_m);
    v("drift_heading_sigma_rad_per_sqrt_m", drift_heading_sigma_rad_per_sqrt_m);
    v("drift_scale_sigma_per_sqrt_m", drift_scale_sigma_per_sqrt_m);
    v("heading_axis", heading_axis);
    v("initial_sigma_m", initial_sigma_m);
    v("initial_sigma_rad", initial_sigma_rad);
    v("file", file);
    v("file_sigma2_a_m2", file_sigma2_a_m2);
    v("file_sigma2_b_m2_per_m", file_sigma2_b_m2_per_m);
    v("file_rot_sigma2_a_rad2", file_rot_sigma2_a_rad2);
    v("file_rot_sigma2_b_rad2_per_m", file_rot_sigma2_b_rad2_per_m);
    v("file_max_gap_s", file_max_gap_s);
  }
  void validate() const;
};

// What a source sees of one frame. Pointers may be null when the source does not need that input.
struct OdometryInput {
  std::size_t frame = 0;
  Timestamp t_ns = 0;
  std::optional<Eigen::Isometry3d> T_w_b_true;  // ground truth at the frame (drift source)
  const std::vector<ImuSample>* imu = nullptr;  // synced samples since the previous frame
  const cv::Mat* image = nullptr;               // decoded grey image (visual sources)
};

struct OdometryOutput {
  PoseEstimate pose;
  std::string reason;  // why the status is not tracking (empty when tracking)
};

class OdometrySource {
 public:
  virtual ~OdometrySource() = default;
  virtual const char* name() const = 0;
  virtual bool needs_ground_truth() const { return false; }
  virtual bool needs_images() const { return false; }
  virtual bool needs_imu() const { return false; }
  // Called once per frame, in frame order (serially).
  virtual OdometryOutput process(const OdometryInput& input) = 0;
};

// Builds the configured source. `dataset` supplies ground truth (drift: required, and the heading axis
// when "auto"); throws ConfigError / DataError naming what is missing.
std::unique_ptr<OdometrySource> make_odometry_source(const OdometryConfig& config, const Dataset& dataset);

}  // namespace loopgate
