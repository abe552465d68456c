// Odometry sources (docs/ekf.md): one interface, chosen by `odometry.source`.
//   drift: ground truth corrupted by a seeded random walk in position, heading and scale, with the
//          covariance of that drift model (for datasets without IMU and controlled experiments);
//   file:  an external trajectory (TUM, KITTI or EuRoC format: file_format), covariance from the growth model
//          sigma^2 = a + b * distance;
//   ekf:   the MSCKF visual-inertial filter of src/stages/ekf on the images and IMU (ekf_odometry.hpp);
//   none:  no poses at all (appearance-only runs): frames carry no pose, frames.csv says
//          odom_status none, trajectory.tum is empty; only run.mode full can detect loops without poses (the
//          pose gate, run.mode odometry and verify need them: config errors).
//   auto:  ekf when the dataset has images, IMU, camera and IMU calibration (and ground truth when
//          ekf.init_mode is ground_truth), else drift when it has ground truth, else none. The default:
//          EuRoC-layout data with IMU gets the ekf, an image folder none.
// Every source emits one PoseEstimate per image. The sources take plain data (a trajectory, ground-truth
// states, calibrations, an axis); pipeline/odometry_factory.hpp builds the configured one from a Dataset.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/enum_names.hpp"
#include "core/pose_covariance.hpp"
#include "core/trajectory_format.hpp"
#include "core/types.hpp"
#include "stages/ekf/ekf_config.hpp"

namespace cv {
class Mat;
}

namespace loopgate {

// odometry.source (see above).
enum class OdometrySourceKind { kDrift, kFile, kEkf, kNone, kAuto };
inline constexpr EnumName<OdometrySourceKind> kOdometrySourceKindNames[] = {
    {OdometrySourceKind::kDrift, "drift"},
    {OdometrySourceKind::kFile, "file"},
    {OdometrySourceKind::kEkf, "ekf"},
    {OdometrySourceKind::kNone, "none"},
    {OdometrySourceKind::kAuto, "auto"}};
constexpr std::span<const EnumName<OdometrySourceKind>> enum_names(OdometrySourceKind) {
  return kOdometrySourceKindNames;
}
// odometry.heading_axis: a world axis, or auto.
enum class HeadingAxis { kAuto, kX, kY, kZ };
inline constexpr EnumName<HeadingAxis> kHeadingAxisNames[] = {
    {HeadingAxis::kAuto, "auto"}, {HeadingAxis::kX, "x"}, {HeadingAxis::kY, "y"}, {HeadingAxis::kZ, "z"}};
constexpr std::span<const EnumName<HeadingAxis>> enum_names(HeadingAxis) {
  return kHeadingAxisNames;
}
// odometry.ekf_up_axis: a signed world axis, or auto.
enum class UpAxis { kAuto, kX, kMinusX, kY, kMinusY, kZ, kMinusZ };
inline constexpr EnumName<UpAxis> kUpAxisNames[] = {
    {UpAxis::kAuto, "auto"}, {UpAxis::kX, "x"}, {UpAxis::kMinusX, "-x"}, {UpAxis::kY, "y"},
    {UpAxis::kMinusY, "-y"}, {UpAxis::kZ, "z"}, {UpAxis::kMinusZ, "-z"}};
constexpr std::span<const EnumName<UpAxis>> enum_names(UpAxis) {
  return kUpAxisNames;
}

struct OdometryConfig {
  OdometrySourceKind source = OdometrySourceKind::kAuto;  // drift | file | ekf | none | auto (see above)
  std::int64_t seed = 1;
  // drift: random walks driven by the distance travelled (per sqrt of metres).
  double drift_position_sigma_m_per_sqrt_m = 0.005;
  double drift_heading_sigma_rad_per_sqrt_m = 0.0003;
  double drift_scale_sigma_per_sqrt_m = 0.0005;
  // Axis of the heading drift in the world frame: x | y | z | auto (normal of the best-fit plane of the
  // ground-truth positions, e.g. -y for KITTI camera frames, z for EuRoC).
  HeadingAxis heading_axis = HeadingAxis::kAuto;
  double initial_sigma_m = 0.01;     // floor added to the position variances
  double initial_sigma_rad = 0.001;  // floor added to the rotation variances
  // file: a trajectory (relative paths are relative to the working directory) in `file_format`: auto (told
  // from its first data line) | tum | kitti (12 columns: row k is the dataset's frame k, timed by the
  // dataset, e.g. KITTI times.txt; 13: a time in seconds first) | euroc (state_groundtruth_estimate0/data.csv
  // columns).
  std::string file;
  TrajectoryFormat file_format = TrajectoryFormat::kAuto;
  double file_sigma2_a_m2 = 0.01;
  double file_sigma2_b_m2_per_m = 0.01;
  double file_rot_sigma2_a_rad2 = 1e-4;
  double file_rot_sigma2_b_rad2_per_m = 1e-5;
  double file_max_gap_s = 0.5;  // a frame farther than this from any trajectory pose is reported lost
  // ekf: the dataset world's up axis (the filter's gravity is along -up): auto | x | -x | y | -y | z | -z.
  // auto: with ekf.init_mode ground_truth the world axis nearest the mean specific force of the IMU rotated
  // into the world by the ground truth (z for EuRoC, -y for KITTI camera-frame worlds); started from the
  // sensors the filter's own gravity-aligned world, z.
  UpAxis ekf_up_axis = UpAxis::kAuto;

  // The keys, in order, for loading, printing and the JSON echo (Self is OdometryConfig or const
  // OdometryConfig).
  template <class Self, class V>
  static void fields(Self& self, V&& v) {
    v("source", self.source);
    v("seed", self.seed);
    v("drift_position_sigma_m_per_sqrt_m", self.drift_position_sigma_m_per_sqrt_m);
    v("drift_heading_sigma_rad_per_sqrt_m", self.drift_heading_sigma_rad_per_sqrt_m);
    v("drift_scale_sigma_per_sqrt_m", self.drift_scale_sigma_per_sqrt_m);
    v("heading_axis", self.heading_axis);
    v("initial_sigma_m", self.initial_sigma_m);
    v("initial_sigma_rad", self.initial_sigma_rad);
    v("file", self.file);
    v("file_format", self.file_format);
    v("file_sigma2_a_m2", self.file_sigma2_a_m2);
    v("file_sigma2_b_m2_per_m", self.file_sigma2_b_m2_per_m);
    v("file_rot_sigma2_a_rad2", self.file_rot_sigma2_a_rad2);
    v("file_rot_sigma2_b_rad2_per_m", self.file_rot_sigma2_b_rad2_per_m);
    v("file_max_gap_s", self.file_max_gap_s);
    v("ekf_up_axis", self.ekf_up_axis);
  }
  void validate() const;
};

// A source's per-image work done ahead of process() (OdometrySource::prepare); each source defines its own.
struct PreparedImage {
  virtual ~PreparedImage() = default;
};

// What a source sees of one frame. Pointers may be null when the source does not need that input.
struct OdometryInput {
  std::size_t frame = 0;
  Timestamp t_ns = 0;
  std::optional<Eigen::Isometry3d> T_w_b_true;  // ground truth at the frame (drift source)
  const std::vector<ImuSample>* imu = nullptr;  // synced samples since the previous frame
  const cv::Mat* image = nullptr;               // decoded grey image (visual sources)
  const PreparedImage* prepared = nullptr;      // prepare(*image), when the caller did it beforehand
};

struct OdometryOutput {
  PoseEstimate pose;
  std::string reason;         // why the status is not tracking (empty when tracking)
  int tracked_features = -1;  // visual sources: features tracked in this image; -1 = not a visual source
  // The covariance of this pose relative to the previous pose this source estimated (T_prev_this;
  // core/pose_covariance.hpp's convention), for the pose graph's odometry edges (posegraph.odometry_cov).
  // nullopt: unknown (the first pose, after a lost frame).
  std::optional<PoseCov> step_cov;
};

// How a source with a start-up phase (the ekf) started, for summary.json and the run's checks
// (run_checks.hpp): which initialiser, where, the state it estimated, and how many frames it tracked since.
struct OdometryStart {
  bool started = false;
  std::string method;        // "static" | "dynamic" | "ground_truth" (the latest start)
  std::size_t frame = 0;     // the dataset frame of the first start
  Timestamp t_ns = 0;        // its time
  double after_first_s = 0;  // seconds of data from the first frame the source saw to the first start
  std::size_t starts = 0;    // the first start and every restart after a loss
  std::size_t frames_seen = 0;
  std::size_t frames_since_start = 0;  // frames from the first start on (it included)
  std::size_t frames_tracking = 0;     // of those, frames with status tracking
  double data_s = 0;                   // seconds from the first to the last frame the source saw
  // The state the first start estimated (the filter world: +z up, yaw 0 for static and dynamic).
  Eigen::Vector3d up_i = Eigen::Vector3d::Zero();  // the world's up in the IMU frame (gravity direction)
  double roll_deg = 0, pitch_deg = 0;
  Eigen::Vector3d v_w_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias_mps2 = Eigen::Vector3d::Zero();
  double scale = 1.0;     // dynamic: the metric scale it found
  double window_s = 0.0;  // seconds of data the decision used
  std::string detail;     // the decision's numbers
  std::string status;     // before the first start: why not yet (each initialiser, with its numbers)
};

class OdometrySource {
 public:
  virtual ~OdometrySource() = default;
  virtual const char* name() const = 0;
  virtual bool needs_ground_truth() const { return false; }
  // False for `none`: process() is not called, frames carry no pose.
  virtual bool estimates_poses() const { return true; }
  virtual bool needs_images() const { return false; }
  virtual bool needs_imu() const { return false; }
  // Called once per frame, in frame order (serially).
  virtual OdometryOutput process(const OdometryInput& input) = 0;
  // The per-image work of a visual source that does not depend on earlier frames (the ekf tracker's image
  // pyramid), for the caller to do where frames run in parallel and hand to process() in
  // OdometryInput::prepared. Const and thread-safe: it may run while process() runs on an earlier frame.
  // nullptr when the source has nothing to prepare or cannot take the image (process() then reports that).
  // Never throws.
  virtual std::shared_ptr<const PreparedImage> prepare(const cv::Mat& /*image*/) const { return nullptr; }
  // Sources that start from the data (the ekf): how they started; nullopt for the others.
  virtual std::optional<OdometryStart> start() const { return std::nullopt; }
};

// odometry.source none: no poses (appearance-only runs).
class NoOdometry final : public OdometrySource {
 public:
  const char* name() const override { return "none"; }
  bool estimates_poses() const override { return false; }
  OdometryOutput process(const OdometryInput& /*input*/) override { return {}; }
};

}  // namespace loopgate
