// When the dynamic initialiser accepts a solution.
// - The alignment must explain most of the tracks vision found consistent: with a minority of the tracks on
//   a moving object it is accepted, with a majority it is refused ("contradicts the structure").
// - The IMU's noise enters the velocity's covariance (the pre-integrated positions' errors carried into the
//   solution), and that covariance of the pre-integrated positions is the simulated noise's.
// - On a straight street at about 12 m/s (IMU vibrating, so the accelerometer's spread passes the excitation
//   check, and noisy at the filter's own densities), a weak surge leaves the scale unknown: refused by the
//   certainty of the velocity; a strong surge starts, with a velocity within what it claims. (Here the
//   pixels' share of that certainty is what refuses; the IMU's share is a few percent at a right solution.)
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "stages/ekf/dynamic_initializer.hpp"
#include "stages/ekf/vi_alignment.hpp"

namespace loopgate {
namespace {

constexpr double kFocalPx = 460.0;
constexpr double kGravity = 9.81;

// The filter's effective noise for the EuRoC ADIS16448 (sensor.yaml times imu_noise_inflation 5).
ImuNoise filter_noise() {
  return ImuNoise{5 * 1.6968e-4, 5 * 1.9393e-5, 5 * 2.0e-3, 5 * 3.0e-3};
}

Eigen::Isometry3d camera_in_imu() {
  // The camera looks along the body x axis (ahead), its y axis down.
  Eigen::Matrix3d R_b_c;
  R_b_c.col(0) = Eigen::Vector3d(0, -1, 0);
  R_b_c.col(1) = Eigen::Vector3d(0, 0, -1);
  R_b_c.col(2) = Eigen::Vector3d(1, 0, 0);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R_b_c;
  T.translation() = Eigen::Vector3d(0.3, 0.0, 0.2);
  return T;
}

// Straight along +x, level, heading fixed: x(t) = v t - a / w^2 sin(w t), so the acceleration is a sin(w t).
struct Street {
  double speed_mps = 12.0;
  double surge_mps2 = 0.0;
  double surge_radps = 1.5;
  double x(double t) const {
    return speed_mps * t - surge_mps2 / (surge_radps * surge_radps) * std::sin(surge_radps * t);
  }
  double v(double t) const { return speed_mps - surge_mps2 / surge_radps * std::cos(surge_radps * t); }
  double a(double t) const { return surge_mps2 * std::sin(surge_radps * t); }
};

struct Drive {
  std::vector<ImuSample> imu;
  std::vector<Timestamp> image_t_ns;
  std::vector<std::vector<FeatureObservation>> observations;
};

Drive simulate(const Street& street, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  const ImuNoise noise = filter_noise();
  const double t0 = 0.0;
  const double duration = 6.0;
  const double dt = 1.0 / 200.0;
  const Eigen::Vector3d gyro_bias(0.002, -0.003, 0.001);
  const Eigen::Vector3d accel_bias(0.03, -0.02, 0.04);
  Drive d;
  const auto samples = static_cast<long>(std::llround(duration / dt));
  for (long k = 0; k <= samples; ++k) {
    const double t = t0 + static_cast<double>(k) * dt;
    const double vib = 0.4 * std::sin(2.0 * std::numbers::pi * 23.0 * t);  // engine and road
    ImuSample s;
    s.t_ns = s_to_ns(t);
    s.gyro_radps =
        gyro_bias + noise.gyro_noise_density / std::sqrt(dt) * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    s.accel_mps2 = Eigen::Vector3d(street.a(t), 0.0, kGravity) + accel_bias +
                   vib * Eigen::Vector3d(1, 1, -1) +
                   noise.accel_noise_density / std::sqrt(dt) * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    d.imu.push_back(s);
  }
  // Landmarks on both sides of the street, 4-12 m from its centre line, up to 200 m ahead.
  std::uniform_real_distribution<double> along(-5.0, 200.0);
  std::uniform_real_distribution<double> side(4.0, 12.0);
  std::uniform_real_distribution<double> height(-1.5, 5.0);
  std::vector<Eigen::Vector3d> landmarks;
  for (int i = 0; i < 1200; ++i) {
    landmarks.emplace_back(along(rng), (i % 2 == 0 ? 1.0 : -1.0) * side(rng), height(rng));
  }
  const Eigen::Isometry3d T_i_c = camera_in_imu();
  for (long k = 1; k < static_cast<long>(duration * 10.0); ++k) {  // 10 Hz
    const double t = t0 + static_cast<double>(k) / 10.0;
    Eigen::Isometry3d T_w_i = Eigen::Isometry3d::Identity();
    T_w_i.translation() = Eigen::Vector3d(street.x(t), 0.0, 1.5);
    const Eigen::Isometry3d T_c_w = (T_w_i * T_i_c).inverse();
    std::vector<FeatureObservation> obs;
    for (std::size_t i = 0; i < landmarks.size(); ++i) {
      const Eigen::Vector3d p = T_c_w * landmarks[i];
      if (p.z() < 1.0 || p.z() > 60.0) continue;
      const Eigen::Vector2d xy = p.head<2>() / p.z();
      if (std::abs(xy.x()) > 0.82 || std::abs(xy.y()) > 0.52) continue;
      FeatureObservation o;
      o.id = i;
      o.xy = xy + 0.5 / kFocalPx * Eigen::Vector2d(n01(rng), n01(rng));
      obs.push_back(o);
    }
    d.image_t_ns.push_back(s_to_ns(t));
    d.observations.push_back(std::move(obs));
  }
  return d;
}

struct Outcome {
  std::optional<InitialState> state;
  std::string status;
  std::vector<std::string> statuses;  // every image's
};

Outcome run(const Drive& d, const ImuNoise& noise) {
  DynamicInitializer init(EkfConfig{}, camera_in_imu(), kFocalPx, noise);
  Outcome out;
  std::size_t next = 0;
  for (std::size_t k = 0; k < d.image_t_ns.size(); ++k) {
    const std::size_t first = next;
    while (next < d.imu.size() && d.imu[next].t_ns <= d.image_t_ns[k]) ++next;
    InitFrame f;
    f.t_ns = d.image_t_ns[k];
    f.imu = std::span<const ImuSample>(d.imu).subspan(first, next - first);
    f.observations = &d.observations[k];
    out.state = init.add_frame(f);
    out.status = init.status();
    out.statuses.push_back(out.status);
    if (out.state) break;
  }
  return out;
}

TEST(EkfInitAcceptance, WeakSurgeOnAStraightStreetIsRefusedAsTooUncertain) {
  Street street;
  street.surge_mps2 = 0.03;
  const Drive d = simulate(street, 11);
  const Outcome r = run(d, filter_noise());
  EXPECT_FALSE(r.state.has_value()) << (r.state ? r.state->detail : std::string());
  // Refused by the certainty of the velocity, not by a check before the alignment.
  std::size_t by_sigma = 0;
  for (const std::string& s : r.statuses) by_sigma += s.find("velocity sigma") != std::string::npos ? 1 : 0;
  EXPECT_GT(by_sigma, 0u) << r.status;
}

TEST(EkfInitAcceptance, StrongSurgeOnTheSameStreetStartsWithinWhatItClaims) {
  Street street;
  street.surge_mps2 = 2.0;
  const Drive d = simulate(street, 11);
  const Outcome r = run(d, filter_noise());
  ASSERT_TRUE(r.state.has_value()) << r.status;
  const InitialState& s = *r.state;
  const double t = ns_to_s(s.state.t_ns);
  EXPECT_LE(t, 5.0) << s.detail;
  // The world's yaw is the start's own: compare the speed, and the velocity in the IMU frame.
  const Eigen::Matrix3d R_est = s.state.q_w_i.toRotationMatrix();
  const Eigen::Vector3d v_est_b = R_est.transpose() * s.state.v_w_mps;
  const Eigen::Vector3d v_true_b(street.v(t), 0.0, 0.0);
  EXPECT_LT(std::abs(v_est_b.norm() - v_true_b.norm()) / v_true_b.norm(), 0.1) << s.detail;
  EXPECT_LT((v_est_b - v_true_b).norm(), 3.0 * std::sqrt(s.vel_cov_m2ps2.trace()) + 0.2) << s.detail;
}

// Cov(e(s), e(t)) of the pre-integrated position error, against a simulation of its sources: white
// accelerometer noise integrated twice, and a walking acceleration error (accelerometer bias random walk
// plus gravity tilted by the gyro's white noise) integrated twice more.
TEST(EkfInitAcceptance, PreintegratedPositionCovarianceIsThatOfTheNoise) {
  AlignInput in;
  in.T_s = {0.0, 0.5, 1.2, 2.0};
  in.accel_noise_density = 0.01;
  in.gyro_noise_density = 0.0008;
  in.accel_random_walk = 0.015;
  in.gravity_mps2 = kGravity;
  const Eigen::MatrixXd S = preintegrated_position_covariance(in);
  ASSERT_EQ(S.rows(), 9);
  ASSERT_EQ(S.cols(), 9);
  EXPECT_TRUE(S.isApprox(S.transpose()));

  // One axis, many runs; the x axis of the tilt's acceleration error is g times the tilt about y.
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n01(0.0, 1.0);
  const double dt = 0.002;
  const int runs = 4000;
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (int r = 0; r < runs; ++r) {
    double p = 0.0;
    double v = 0.0;
    double walk = 0.0;  // bias + g * tilt
    Eigen::Vector3d e = Eigen::Vector3d::Zero();
    std::size_t next = 1;
    for (int k = 0; k < static_cast<int>(std::lround(2.0 / dt)); ++k) {
      const double a = walk + in.accel_noise_density / std::sqrt(dt) * n01(rng);
      p += v * dt + 0.5 * a * dt * dt;
      v += a * dt;
      walk += std::sqrt(dt) * (in.accel_random_walk * n01(rng) + kGravity * in.gyro_noise_density * n01(rng));
      const double t = (k + 1) * dt;
      if (next < in.T_s.size() && std::abs(t - in.T_s[next]) < 0.5 * dt)
        e(static_cast<Eigen::Index>(next++ - 1)) = p;
    }
    sum += e * e.transpose();
  }
  const Eigen::Matrix3d sample = sum / runs;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(sample(i, j) / S(3 * i, 3 * j), 1.0, 0.12)
          << i << " " << j << ": " << sample(i, j) << " vs " << S(3 * i, 3 * j);
    }
  }
  // Isotropic and uncorrelated between axes.
  EXPECT_DOUBLE_EQ(S(4, 4), S(3, 3));
  EXPECT_DOUBLE_EQ(S(3, 4), 0.0);
}

// The alignment itself on a window built from a known motion (no rotation, a surge and a sway), the tracks
// of static landmarks with 0.5 px of noise, and some tracks on an object that moves (3.6 m/s against the
// street), consistent with no static point seen from the IMU's path. The tracks given to the alignment are
// those vision found consistent; a solution must explain most of them.
struct AlignCase {
  AlignInput in;
  Eigen::Vector3d v0_true = Eigen::Vector3d::Zero();
};

AlignCase make_align_case(int corrupted_per_ten) {
  std::mt19937_64 rng(5);
  std::normal_distribution<double> n01(0.0, 1.0);
  const EkfConfig config;
  const Eigen::Isometry3d T_i_c = camera_in_imu();
  AlignCase c;
  AlignInput& in = c.in;
  in.R_b_c = T_i_c.linear();
  in.p_b_c = T_i_c.translation();
  in.sigma_xy = config.pixel_sigma_px / kFocalPx;
  in.outlier_xy = config.triangulation_max_reproj_sigma * config.pixel_sigma_px / kFocalPx;
  in.gravity_mps2 = kGravity;
  const Eigen::Vector3d g_b0(0.0, 0.0, -kGravity);
  auto pos = [](double t) {
    return Eigen::Vector3d(12.0 * t - 2.0 / 2.25 * std::sin(1.5 * t), 0.5 * std::sin(1.3 * t) - 0.65 * t,
                           0.0);
  };
  c.v0_true = Eigen::Vector3d(12.0 - 2.0 / 1.5, 0.0, 0.0);  // the derivative of pos at 0
  const std::size_t n = 21;
  std::vector<Eigen::Vector3d> p(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double T = 0.1 * static_cast<double>(k);
    p[k] = pos(T) - pos(0.0);
    in.T_s.push_back(T);
    in.R_b0_bk.push_back(Eigen::Matrix3d::Identity());
    in.alpha.push_back(p[k] - c.v0_true * T - 0.5 * T * T * g_b0);
    in.J_alpha_ba.push_back(-0.5 * T * T * Eigen::Matrix3d::Identity());
    in.J_R_bg.push_back(-T * Eigen::Matrix3d::Identity());
  }
  const double unit = (in.R_b_c.transpose() * (p[n - 1] - p[0])).norm();
  for (std::size_t k = 0; k < n; ++k) in.sfm_c0_ck.push_back(in.R_b_c.transpose() * p[k] / unit);
  std::uniform_real_distribution<double> along(2.0, 60.0);
  std::uniform_real_distribution<double> side(4.0, 12.0);
  std::uniform_real_distribution<double> height(-1.5, 4.0);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d P(along(rng), (i % 2 == 0 ? 1.0 : -1.0) * side(rng), height(rng));
    const bool corrupt = i % 10 < corrupted_per_ten;
    std::vector<std::pair<std::size_t, Eigen::Vector2d>> obs;
    for (std::size_t k = 0; k < n; ++k) {
      // A point on the moving object moves with it: -3 m/s along, 2 m/s across the street.
      const Eigen::Vector3d P_k =
          corrupt ? Eigen::Vector3d(P + Eigen::Vector3d(-3.0, 2.0, 0.0) * in.T_s[k]) : P;
      const Eigen::Vector3d pc = in.R_b_c.transpose() * (P_k - p[k] - in.p_b_c);
      if (pc.z() < 1.0) continue;
      const Eigen::Vector2d xy =
          pc.head<2>() / pc.z() + in.sigma_xy * 0.5 * Eigen::Vector2d(n01(rng), n01(rng));
      obs.emplace_back(k, xy);
    }
    if (obs.size() < 3) continue;
    in.tracks.push_back(std::move(obs));
    in.sfm_points_c0.push_back(in.R_b_c.transpose() * (P - in.p_b_c) / unit);
  }
  return c;
}

TEST(EkfInitAcceptance, AlignmentExplainingMostTracksIsAccepted) {
  const AlignCase c = make_align_case(2);  // a fifth of the tracks on a moving object
  std::string why;
  const std::optional<AlignOutput> al = align_known_rotations(c.in, &why);
  ASSERT_TRUE(al.has_value()) << why;
  EXPECT_GT(al->tracks_used, al->tracks_dropped);
  EXPECT_LT((al->x.head<3>() - c.v0_true).norm(), 0.05 * c.v0_true.norm())
      << al->x.head<3>().transpose() << " vs " << c.v0_true.transpose();
}

TEST(EkfInitAcceptance, AlignmentThatMostTracksContradictIsRefused) {
  const AlignCase c = make_align_case(6);  // six tenths on a moving object: the static scene is a minority
  std::string why;
  const std::optional<AlignOutput> al = align_known_rotations(c.in, &why);
  EXPECT_FALSE(al.has_value()) << "velocity " << al->x.head<3>().transpose() << ", " << al->tracks_used
                               << " tracks kept, " << al->tracks_dropped << " dropped";
  EXPECT_NE(why.find("contradicts the structure"), std::string::npos) << why;
}

// With the IMU's noise the velocity's covariance grows by the pre-integration's share, and only then: the
// pixel-noise covariance is unchanged, and without noise both are equal.
TEST(EkfInitAcceptance, ImuNoiseWidensTheVelocityCovarianceOnly) {
  AlignCase c = make_align_case(0);
  std::string why;
  const std::optional<AlignOutput> exact = align_known_rotations(c.in, &why);
  ASSERT_TRUE(exact.has_value()) << why;
  EXPECT_TRUE(exact->cov_imu.isApprox(exact->cov));
  const ImuNoise noise = filter_noise();
  c.in.accel_noise_density = noise.accel_noise_density;
  c.in.gyro_noise_density = noise.gyro_noise_density;
  c.in.accel_random_walk = noise.accel_random_walk;
  const std::optional<AlignOutput> noisy = align_known_rotations(c.in, &why);
  ASSERT_TRUE(noisy.has_value()) << why;
  EXPECT_TRUE(noisy->cov.isApprox(exact->cov));
  const double v_imu = noisy->cov_imu.topLeftCorner<3, 3>().trace();
  const double v_pix = noisy->cov.topLeftCorner<3, 3>().trace();
  EXPECT_GT(v_imu, v_pix);
  using Mat = Eigen::Matrix<double, kAlignDim, kAlignDim>;
  const Mat extra = noisy->cov_imu - noisy->cov;
  const double min_eig = Eigen::SelfAdjointEigenSolver<Mat>(extra).eigenvalues().minCoeff();
  EXPECT_GE(min_eig, -1e-12 * extra.norm());
}

}  // namespace
}  // namespace loopgate
