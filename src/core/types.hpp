// Value types shared by every part of loopgate. Names carry frames and units:
// T_a_b maps points from frame b to frame a; t_ns is a timestamp in integer nanoseconds.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

namespace loopgate {

using Timestamp = std::int64_t;  // nanoseconds

constexpr double kNsPerS = 1e9;
inline double ns_to_s(Timestamp t_ns) {
  return static_cast<double>(t_ns) / kNsPerS;
}
Timestamp s_to_ns(double t_s);  // rounds to the nearest ns

// One IMU reading in the IMU (sensor) frame.
struct ImuSample {
  Timestamp t_ns = 0;
  Eigen::Vector3d gyro_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_mps2 = Eigen::Vector3d::Zero();
};

// A timestamped rigid body pose in the world frame.
struct StampedPose {
  Timestamp t_ns = 0;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
};

// Full ground-truth state as EuRoC provides it (velocity and biases when known).
struct GroundTruthState {
  Timestamp t_ns = 0;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
  Eigen::Vector3d v_w_mps = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias_radps = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias_mps2 = Eigen::Vector3d::Zero();
};

enum class OdometryStatus { kInitialising, kTracking, kLost };
const char* to_string(OdometryStatus status);

// What an odometry source emits per image. Covariance order: position (3) then rotation (3, right
// perturbation of T_w_b), in m^2 / rad^2.
struct PoseEstimate {
  Timestamp t_ns = 0;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
  Eigen::Vector3d v_w_mps = Eigen::Vector3d::Zero();
  bool has_velocity = false;
  Eigen::Matrix<double, 6, 6> cov = Eigen::Matrix<double, 6, 6>::Zero();
  OdometryStatus status = OdometryStatus::kInitialising;

  Eigen::Matrix3d position_cov_m2() const { return cov.topLeftCorner<3, 3>(); }
  // sqrt of the largest eigenvalue of the position covariance (frames.csv's sigma_m), metres.
  double position_sigma_m() const;
};

// What a loop detector concluded for one query frame: one vocabulary for every method (DIRD's sequence
// matcher, SeqSLAM), written to frames.csv ("detection") and counted in summary.json ("detection").
enum class FrameOutcome {
  kNoCandidate,     // nothing to match (DIRD: no similarity above tau1; SeqSLAM: no sequence)
  kBelowThreshold,  // a best match that is not good enough (DIRD: DP <= tau3 L; SeqSLAM: ratio too high)
  kSuppressed,      // above the threshold, all removed by non-maximum suppression (DIRD)
  kLoop,            // at least one loop closure reported
};
constexpr std::size_t kFrameOutcomeCount = 4;
// "no candidate", "below threshold", "suppressed", "loop".
const char* to_string(FrameOutcome outcome);

// One query frame's detection result as the outputs show it.
struct FrameDetection {
  FrameOutcome outcome = FrameOutcome::kNoCandidate;
  std::string label;        // the method's word for the outcome (DIRD: to_string(outcome); SeqSLAM: "no
                            // match", "rejected", "loop")
  std::int64_t match = -1;  // the best earlier / reference frame, in the caller's index space; -1: none
  double score = 0.0;       // its score (DIRD: DP value, higher is better; SeqSLAM: ratio, lower is better)
  std::string reason;       // why, in words
};

enum class DistortionModel { kNone, kRadTan, kEquidistant };
const char* to_string(DistortionModel model);

// Pinhole camera with optional distortion (EuRoC conventions: radtan k1 k2 p1 p2, equidistant k1..k4).
struct CameraCalibration {
  int width_px = 0;
  int height_px = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  DistortionModel distortion_model = DistortionModel::kNone;
  std::vector<double> distortion;                           // coefficients of distortion_model
  Eigen::Isometry3d T_b_c = Eigen::Isometry3d::Identity();  // camera -> body (EuRoC T_BS)
  double rate_hz = 0;
};

// IMU noise model, EuRoC convention (continuous-time densities).
struct ImuCalibration {
  double gyro_noise_density = 0;   // rad / s / sqrt(Hz)
  double gyro_random_walk = 0;     // rad / s^2 / sqrt(Hz)
  double accel_noise_density = 0;  // m / s^2 / sqrt(Hz)
  double accel_random_walk = 0;    // m / s^3 / sqrt(Hz)
  double rate_hz = 0;
  Eigen::Isometry3d T_b_i = Eigen::Isometry3d::Identity();  // imu -> body (EuRoC T_BS)
};

}  // namespace loopgate
