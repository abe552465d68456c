// Dynamic initialisation of the ekf odometry: visual-inertial alignment over a short window of images taken
// while moving (after VINS-Mono, Qin et al. 2018, and the closed-form linear initialisation of Dong-Si and
// Mourikis 2012). Over a sliding window of images:
//   1. structure from motion up to scale (essential matrix between the oldest image and the one with the
//      largest rotation-compensated parallax, triangulation, PnP, alternating refinement): its rotations and
//      its set of consistent tracks;
//   2. IMU pre-integration between consecutive images, with Jacobians on both biases;
//   3. the gyro bias from the rotations of vision against the pre-integrated gyro, then re-integration;
//   4. alignment with the gyro's rotations: the velocity and gravity at the first image, the accelerometer
//      bias (under its prior) and every track's position, from equations linear in all of them; gravity is
//      then held on its sphere and the equations re-weighted into reprojection errors. The metric scale
//      comes from the pre-integrated accelerometer directly.
// It refuses (and says why in status()) when the parallax, the IMU excitation, the gravity norm of the
// unconstrained solve, the reprojection residual, the certainty of the velocity (the scale) or the
// translation is out of bounds (EkfConfig dynamic_init_*).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <deque>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/imu_propagator.hpp"
#include "stages/ekf/initializer.hpp"
#include "stages/ekf/vi_alignment.hpp"

namespace loopgate {

using FeatureMap = std::unordered_map<std::uint64_t, Eigen::Vector2d>;  // track id -> normalised coordinates

class DynamicInitializer {
 public:
  // T_i_c: camera -> IMU (the camera pose in the IMU frame); focal_px turns normalised coordinates into the
  // pixels of the parallax and residual thresholds; noise: the IMU's effective noise densities, whose
  // pre-integrated errors give the certainty of the velocity reported beside the one that decides (all zero:
  // the pre-integration taken as exact).
  DynamicInitializer(const EkfConfig& config, const Eigen::Isometry3d& T_i_c, double focal_px,
                     const ImuNoise& noise = ImuNoise{});

  // One call per image, in time order. Returns the initial state at this image's time once the alignment
  // over the window succeeds (InitialState::frame counts the images given since construction or reset()).
  std::optional<InitialState> add_frame(const InitFrame& frame);

  // InitialState::scale is the metric translation of the camera between the first and the last image of the
  // window.

  // Why it has not succeeded yet, with the numbers behind it (or what succeeded).
  const std::string& status() const { return status_; }

  void reset();

 private:
  struct Frame {
    Timestamp t_ns = 0;
    FeatureMap features;         // id -> normalised coordinates
    std::vector<ImuSample> imu;  // samples from the previous image's time (interpolated) to this one's
  };

  // One alignment attempt over the window: what each step hands to the next.
  struct Attempt {
    const std::deque<Frame>* frames = nullptr;  // the images it uses: the window, or its newest part
    double span_s = 0.0;
    std::vector<Preintegrated> pre;  // per image k >= 1: the IMU from image k-1 to k, under the gyro bias bg
    Eigen::Vector3d bg = Eigen::Vector3d::Zero();
    std::size_t best = 0;  // the SfM pair: image 0 of `frames` and this one
    double acc_std = 0.0;
    double vision_parallax = 0.0;
    double max_reproj = 0.0;                                    // normalised
    std::vector<Eigen::Isometry3d> T_ck_c0;                     // SfM poses (SfM units)
    std::unordered_map<std::uint64_t, Eigen::Vector3d> points;  // SfM points in c0
    std::vector<Eigen::Matrix3d> R_c0_bk;
    std::vector<Eigen::Vector3d> p_c0_ck;  // in units of the first-to-last camera translation
    double unit = 1.0;                     // that translation in SfM units
    AlignInput in;
    std::vector<Eigen::Vector3d> beta;  // pre-integrated velocity in b0 (zero accelerometer bias)
    std::vector<Eigen::Matrix3d> J_beta_ba;
  };

  std::optional<InitialState> try_align();
  void integrate_all(Attempt* at) const;
  // The index in the window (from `start` on) of the first image the attempt uses (its SfM pair in
  // at->best), or nothing (status_ says why).
  std::optional<std::size_t> choose_sfm_pair(std::size_t start, double span_s, Attempt* at);
  bool measure_excitation(Attempt* at);
  bool relative_pose(Attempt* at);
  void triangulate_new(std::size_t k, Attempt* at) const;
  bool pose_all_images(Attempt* at);
  bool estimate_gyro_bias(Attempt* at);
  void build_align_input(Attempt* at) const;
  std::optional<InitialState> finish(const Attempt& at);

  EkfConfig config_;
  Eigen::Isometry3d T_i_c_;
  double focal_px_ = 1.0;
  ImuNoise noise_;
  std::deque<Frame> window_;
  std::optional<ImuSample> last_sample_;  // the latest IMU sample seen (start of the next interval)
  std::size_t frames_seen_ = 0;
  std::string status_ = "no image yet";
};

}  // namespace loopgate
