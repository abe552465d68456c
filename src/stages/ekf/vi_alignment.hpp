// The pieces of the dynamic initialiser that are plain numerics: IMU pre-integration between images,
// multi-view triangulation, PnP, and the visual-inertial alignment with known rotations (velocity, gravity,
// both biases and the tracks on the reprojection errors) with the covariance the filter starts from.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/types.hpp"
#include "stages/ekf/ekf_config.hpp"
#include "stages/ekf/imu_propagator.hpp"

namespace loopgate {

// Pre-integrated IMU between two images, in the frame of the IMU at the first (b_k), for a gyro bias bg:
// R_bk_bk1, the velocity and position increments of the specific force, and their Jacobians on bg.
struct Preintegrated {
  double dt_s = 0.0;
  Eigen::Matrix3d dR = Eigen::Matrix3d::Identity();
  Eigen::Vector3d dv = Eigen::Vector3d::Zero();
  Eigen::Vector3d dp = Eigen::Vector3d::Zero();
  Eigen::Matrix3d J_R_bg = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d J_v_bg = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d J_p_bg = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d J_v_ba = Eigen::Matrix3d::Zero();  // d dv / d ba (the bias is subtracted from the reading)
  Eigen::Matrix3d J_p_ba = Eigen::Matrix3d::Zero();
};

// Integrates `samples` (time-ordered, the first at or before t_a when available) over [t_a, t_b]: between two
// readings the mean of both, before the first and after the last the nearest reading held.
Preintegrated preintegrate(const std::vector<ImuSample>& samples, Timestamp t_a, Timestamp t_b,
                           const Eigen::Vector3d& bg);

// Linear multi-view triangulation of a point in c0 from normalised observations in cameras with poses
// T_ck_c0. Returns false when the point is behind a camera or poorly constrained.
bool triangulate(const std::vector<Eigen::Isometry3d>& T_ck_c0, const std::vector<Eigen::Vector2d>& xy,
                 double max_reproj, Eigen::Vector3d* p_c0);

// Camera pose T_c_c0 of an image from its normalised observations xy of the points p_c0 (RANSAC PnP, at
// least 10 correspondences and 8 inliers within max_reproj), starting from `guess`; false (T_out untouched)
// when it fails.
bool pnp_ransac(const std::vector<Eigen::Vector3d>& p_c0, const std::vector<Eigen::Vector2d>& xy,
                double max_reproj, const Eigen::Isometry3d& guess, Eigen::Isometry3d* T_out);

// Visual-inertial alignment with known rotations (the gyro's, bias-corrected; after the closed-form linear
// initialisation of Dong-Si and Mourikis 2012 as used by OpenVINS' dynamic initialiser). The unknowns are
// x = [v0, g, ba]: the velocity and gravity in the IMU frame at the first image (b0) and the accelerometer
// bias, plus the position P_f of every track in b0. An observation (u, v) of track f in image k gives two
// equations, linear in all of them:
//   [1 0 -u; 0 1 -v] R_ck_b0 (P_f - p_k - R_k p_b_c) = 0,   p_k = v0 T_k + g T_k^2 / 2 + alpha_k + J_k ba,
// which is the reprojection error times the depth. A closed-form solve of them gives the first guess; the
// reprojection errors themselves are then minimised (below). The tracks are eliminated by their Schur
// complement and |g| is held on its sphere. Because the pre-integrated accelerometer gives metric positions
// directly, there is no up-to-scale structure whose scale could be biased by its noise.
struct AlignInput {
  std::vector<Eigen::Matrix3d> R_b0_bk;  // rotation of image k's IMU frame in b0
  std::vector<double> T_s;               // time since the first image
  std::vector<Eigen::Vector3d> alpha;    // pre-integrated position in b0 (zero bias), and its bias Jacobian
  std::vector<Eigen::Matrix3d> J_alpha_ba;
  std::vector<Eigen::Matrix3d> J_R_bg;  // right Jacobian of R_b0_bk on the gyro bias
  Eigen::Matrix3d R_b_c;
  Eigen::Vector3d p_b_c;
  std::vector<std::vector<std::pair<std::size_t, Eigen::Vector2d>>> tracks;  // (image, normalised xy)
  std::vector<Eigen::Vector3d> sfm_points_c0;  // per track: its SfM point (c0, SfM units)
  std::vector<Eigen::Vector3d> sfm_c0_ck;      // per image: the camera position of the SfM (c0, SfM units)
  double sigma_xy = 1.0 / 460.0;               // normalised-coordinate noise
  double sigma_ba_mps2 = 0.1;                  // prior of the accelerometer bias (zero mean)
  double sigma_bg_radps = 0.01;                // prior of the gyro bias correction (zero mean)
  double gravity_mps2 = 9.81;
  double outlier_xy = 5.0 / 460.0;  // a track with an observation further than this is dropped
  // The IMU's noise (the filter's effective densities; zero: not modelled). The alignment takes the
  // pre-integrated positions as exact; these give the covariance of their errors, propagated into
  // AlignOutput::cov_imu.
  double accel_noise_density = 0.0;  // m / s^2 / sqrt(Hz)
  double gyro_noise_density = 0.0;   // rad / s / sqrt(Hz)
  double accel_random_walk = 0.0;    // m / s^3 / sqrt(Hz)
};

constexpr int kAlignDim = 12;  // v0, g, ba, dbg

struct AlignOutput {
  Eigen::Matrix<double, kAlignDim, 1> x = Eigen::Matrix<double, kAlignDim, 1>::Zero();
  Eigen::Matrix<double, kAlignDim, kAlignDim> cov = Eigen::Matrix<double, kAlignDim, kAlignDim>::Identity();
  // cov plus the pre-integration's errors carried into the solution: the solve's sensitivity to an error
  // of each image's pre-integrated position (tracks eliminated) applied to their covariance (white noise of
  // the accelerometer; the gyro's white noise tilting gravity and the accelerometer bias's random walk,
  // both integrated three times). On a weakly excited window the metric scale rests on a few centimetres
  // of pre-integrated deviation from constant velocity; this is the covariance that says so.
  Eigen::Matrix<double, kAlignDim, kAlignDim> cov_imu =
      Eigen::Matrix<double, kAlignDim, kAlignDim>::Identity();
  double g_norm_free = 0.0;  // |g| of one step with gravity's norm free, from the solution
  double rms_xy = 0.0;       // reprojection RMS of the tracks kept (normalised)
  std::size_t tracks_used = 0;
  std::size_t tracks_dropped = 0;
  std::vector<Eigen::Vector3d> p_b0_bk;  // positions of the IMU at the images
};

// Gauss-Newton (Levenberg-Marquardt) on the reprojection errors themselves, from the linear guess. The
// unknowns are x = [v0, g, ba, dbg] - dbg a correction of the gyro bias that turns every rotation by
// Exp(J_k dbg) - with g moved only on its sphere, and every track's position (eliminated by its Schur
// complement); both biases are under their zero-mean priors. Tracks behind a camera or with an observation
// further than outlier_xy are dropped as the solve goes. One more step with gravity's norm free gives the
// |g| the data alone ask for: a check of the whole solve. Refused (nothing, with why) when fewer than 8
// tracks are left, or when the solution keeps fewer tracks than it drops: the tracks given are those vision
// found consistent, and a solution most of them contradict is not theirs.
std::optional<AlignOutput> align_known_rotations(const AlignInput& in, std::string* why);

// Covariance of the errors of the pre-integrated IMU positions at the images 1..n-1 of the window (3(n-1)
// square, isotropic per axis): accelerometer white noise integrated twice, Cov(e(s), e(t)) = qa (m^2 M / 2 -
// m^3 / 6), plus an acceleration error that itself walks (the gyro's white noise tilting gravity, |g|^2 qg,
// and the accelerometer bias's random walk) integrated twice more, (|g|^2 qg + qb) int_0^m (s-u)^2 (t-u)^2
// / 4 du; m, M the smaller and larger of the two times since the first image.
Eigen::MatrixXd preintegrated_position_covariance(const AlignInput& in);

// The covariance the filter starts from: the alignment's own (its normal equations at the solution, scaled by
// the residuals), carried to the state at the last image with its cross terms, rows [attitude as the
// filter's body perturbation, velocity (world), gyro bias, accelerometer bias], columns the alignment's
// unknowns [v0, g, ba, dbg] (b0). Gravity's direction turns the world by phi = z x (R_w dg) / |g| (tilt),
// which also turns the velocity; dbg turns the last rotation by J_R_bg dbg. The floors of the config are
// added (tilt and velocity: the pre-integration taken as exact; yaw: unobservable, set to zero).
Eigen::Matrix<double, 12, 12> joint_start_covariance(const AlignOutput& al, const AlignInput& in,
                                                     const Eigen::Matrix3d& R_w, const Eigen::Matrix3d& R_n,
                                                     const Eigen::Vector3d& v_n,
                                                     const Eigen::Matrix<double, 3, 9>& J_vn,
                                                     const EkfConfig& config);

}  // namespace loopgate
