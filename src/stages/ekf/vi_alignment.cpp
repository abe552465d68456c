#include "stages/ekf/vi_alignment.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/core/eigen.hpp>

#include "core/geometry.hpp"

namespace loopgate {
namespace {

std::string fmt(const char* format, auto... args) {
  char buf[1024];
  std::snprintf(buf, sizeof(buf), format, args...);
  return buf;
}

Eigen::Matrix<double, 3, 2> tangent_basis(const Eigen::Vector3d& u) {
  const Eigen::Vector3d helper = std::abs(u.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  Eigen::Matrix<double, 3, 2> B;
  B.col(0) = u.cross(helper).normalized();
  B.col(1) = u.cross(B.col(0));
  return B;
}

// Position of the IMU at image k in b0 for x = [v0, g, ba].
Eigen::Vector3d imu_position(const AlignInput& in, std::size_t k, const Eigen::Matrix<double, 9, 1>& x) {
  const double T = in.T_s[k];
  return x.segment<3>(0) * T + 0.5 * T * T * x.segment<3>(3) + in.alpha[k] +
         in.J_alpha_ba[k] * x.segment<3>(6);
}

// The first guess, from the structure from motion: its camera positions are metric up to one scale s, so
//   v0 T_k + g T_k^2 / 2 - s R_b_c c_k = p_b_c - R_k p_b_c - alpha_k      (c_k: camera k in c0, SfM units)
// is linear in [v0, g, s] (the accelerometer bias at zero); gravity is then put on its sphere and v0, s
// solved again. The tracks start at their SfM points, scaled. (The reprojection equations themselves, solved
// in closed form, would favour a shrunken scene: their residuals scale with the depths.)
bool linear_guess(const AlignInput& in, Eigen::Matrix<double, 9, 1>* x_out,
                  std::vector<std::optional<Eigen::Vector3d>>* P_out, std::string* why) {
  const std::size_t n = in.T_s.size();
  auto solve = [&](bool fixed_g, const Eigen::Vector3d& g_fixed, Eigen::VectorXd* sol) {
    const int cols = fixed_g ? 4 : 7;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(3 * n), cols);
    Eigen::VectorXd b = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(3 * n));
    for (std::size_t k = 0; k < n; ++k) {
      const auto r = static_cast<Eigen::Index>(3 * k);
      const double T = in.T_s[k];
      A.block(r, 0, 3, 3) = T * Eigen::Matrix3d::Identity();
      Eigen::Vector3d rhs = in.p_b_c - in.R_b0_bk[k] * in.p_b_c - in.alpha[k];
      if (fixed_g) {
        rhs -= 0.5 * T * T * g_fixed;
      } else {
        A.block(r, 3, 3, 3) = 0.5 * T * T * Eigen::Matrix3d::Identity();
      }
      A.block(r, cols - 1, 3, 1) = -(in.R_b_c * in.sfm_c0_ck[k]);
      b.segment(r, 3) = rhs;
    }
    *sol = A.colPivHouseholderQr().solve(b);
    return sol->allFinite();
  };
  Eigen::VectorXd sol;
  if (!solve(false, Eigen::Vector3d::Zero(), &sol) || sol.segment<3>(3).norm() < 1e-6) {
    *why = "alignment: singular first guess";
    return false;
  }
  const Eigen::Vector3d g = sol.segment<3>(3).normalized() * in.gravity_mps2;
  if (!solve(true, g, &sol) || !(sol(3) > 0.0)) {
    *why =
        fmt("alignment: the structure's scale comes out %.4g (not positive)", sol.size() > 3 ? sol(3) : 0.0);
    return false;
  }
  const double scale = sol(3);
  x_out->setZero();
  x_out->segment<3>(0) = sol.head<3>();
  x_out->segment<3>(3) = g;
  P_out->assign(in.tracks.size(), std::nullopt);
  for (std::size_t f = 0; f < in.tracks.size(); ++f) {
    (*P_out)[f] = in.R_b_c * (scale * in.sfm_points_c0[f]) + in.p_b_c;
  }
  return true;
}

}  // namespace

// Integrates `samples` (time-ordered, the first at or before t_a when available) over [t_a, t_b]: between two
// readings the mean of both, before the first and after the last the nearest reading held.
Preintegrated preintegrate(const std::vector<ImuSample>& samples, Timestamp t_a, Timestamp t_b,
                           const Eigen::Vector3d& bg) {
  Preintegrated pi;
  pi.dt_s = ns_to_s(t_b - t_a);
  auto step = [&](const Eigen::Vector3d& w_raw, const Eigen::Vector3d& a, double dt) {
    if (dt <= 0.0) return;
    const Eigen::Vector3d w = w_raw - bg;
    const Eigen::Matrix3d a_x = skew(a);
    pi.dp += pi.dv * dt + 0.5 * pi.dR * a * dt * dt;
    pi.J_p_bg += pi.J_v_bg * dt - 0.5 * pi.dR * a_x * pi.J_R_bg * dt * dt;
    pi.J_p_ba += pi.J_v_ba * dt - 0.5 * pi.dR * dt * dt;
    pi.J_v_ba -= pi.dR * dt;
    pi.dv += pi.dR * a * dt;
    pi.J_v_bg -= pi.dR * a_x * pi.J_R_bg * dt;
    const Eigen::Matrix3d dR_step = so3_exp(w * dt);
    pi.J_R_bg = dR_step.transpose() * pi.J_R_bg - so3_right_jacobian(w * dt) * dt;
    pi.dR = pi.dR * dR_step;
  };
  if (samples.empty()) return pi;
  Timestamp t = t_a;
  if (samples.front().t_ns > t_a) {
    const Timestamp t_end = std::min(samples.front().t_ns, t_b);
    step(samples.front().gyro_radps, samples.front().accel_mps2, ns_to_s(t_end - t));
    t = t_end;
  }
  for (std::size_t i = 0; i + 1 < samples.size() && t < t_b; ++i) {
    const ImuSample& s0 = samples[i];
    const ImuSample& s1 = samples[i + 1];
    const Timestamp lo = std::max(s0.t_ns, t);
    const Timestamp hi = std::min(s1.t_ns, t_b);
    if (hi <= lo) continue;
    step(0.5 * (s0.gyro_radps + s1.gyro_radps), 0.5 * (s0.accel_mps2 + s1.accel_mps2), ns_to_s(hi - lo));
    t = hi;
  }
  if (t < t_b) step(samples.back().gyro_radps, samples.back().accel_mps2, ns_to_s(t_b - t));
  return pi;
}

// Linear multi-view triangulation of a point in c0 from normalised observations in cameras with poses
// T_ck_c0. Returns false when the point is behind a camera or poorly constrained.
bool triangulate(const std::vector<Eigen::Isometry3d>& T_ck_c0, const std::vector<Eigen::Vector2d>& xy,
                 double max_reproj, Eigen::Vector3d* p_c0) {
  const int n = static_cast<int>(xy.size());
  Eigen::MatrixXd A(2 * n, 4);
  for (int k = 0; k < n; ++k) {
    const Eigen::Matrix<double, 3, 4> P = T_ck_c0[static_cast<std::size_t>(k)].matrix().topRows<3>();
    A.row(2 * k) = xy[static_cast<std::size_t>(k)].x() * P.row(2) - P.row(0);
    A.row(2 * k + 1) = xy[static_cast<std::size_t>(k)].y() * P.row(2) - P.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  if (std::abs(h(3)) < 1e-12) return false;
  *p_c0 = h.head<3>() / h(3);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d pc = T_ck_c0[static_cast<std::size_t>(k)] * *p_c0;
    if (pc.z() <= 1e-6) return false;
    if ((pc.head<2>() / pc.z() - xy[static_cast<std::size_t>(k)]).norm() > max_reproj) return false;
  }
  return true;
}

bool pnp_ransac(const std::vector<Eigen::Vector3d>& p_c0, const std::vector<Eigen::Vector2d>& xy,
                double max_reproj, const Eigen::Isometry3d& guess, Eigen::Isometry3d* T_out) {
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  for (std::size_t i = 0; i < p_c0.size() && i < xy.size(); ++i) {
    obj.emplace_back(p_c0[i].x(), p_c0[i].y(), p_c0[i].z());
    img.emplace_back(xy[i].x(), xy[i].y());
  }
  if (obj.size() < 10) return false;
  cv::Mat R_guess;
  cv::Mat rvec;
  cv::Mat tvec;
  cv::eigen2cv(Eigen::Matrix3d(guess.linear()), R_guess);
  cv::Rodrigues(R_guess, rvec);
  cv::eigen2cv(Eigen::Vector3d(guess.translation()), tvec);
  cv::Mat inliers;
  if (!cv::solvePnPRansac(obj, img, cv::Mat::eye(3, 3, CV_64F), cv::Mat(), rvec, tvec, true, 100,
                          static_cast<float>(max_reproj), 0.99, inliers, cv::SOLVEPNP_ITERATIVE) ||
      inliers.rows < 8) {
    return false;
  }
  cv::Mat R_est;
  cv::Rodrigues(rvec, R_est);
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  cv::cv2eigen(R_est, R);
  cv::cv2eigen(tvec, t);
  T_out->setIdentity();
  T_out->linear() = R;
  T_out->translation() = t;
  return true;
}

namespace {

using VecX = Eigen::Matrix<double, kAlignDim, 1>;
// The other starts of the solve: the linear guess's velocity and scene scaled by 2^(k/2), k = -2..2 but 0.
constexpr std::array<double, 4> kAlignScaleStarts{0.5, 0.70710678118654752, 1.4142135623730950, 2.0};
using MatX = Eigen::Matrix<double, kAlignDim, kAlignDim>;
using VecZ = Eigen::Matrix<double, kAlignDim - 1, 1>;
using MatZ = Eigen::Matrix<double, kAlignDim - 1, kAlignDim - 1>;
using MatXZ = Eigen::Matrix<double, kAlignDim, kAlignDim - 1>;
using TrackPoints = std::vector<std::optional<Eigen::Vector3d>>;

// The normal equations of one Gauss-Newton step in all unknowns (tracks eliminated), with the priors.
struct AlignStep {
  MatX N = MatX::Zero();
  VecX q = VecX::Zero();
  std::vector<std::optional<Eigen::Matrix3d>> Haa_inv;
  std::vector<Eigen::Matrix<double, 3, kAlignDim>> Hab;
  std::vector<Eigen::Vector3d> ga;
  std::size_t active = 0;
};

// The reprojection problem of the alignment: x = [v0, g, ba, dbg] and every track's position P, the
// reprojection errors in units of the pixel sigma squared, both biases under their zero-mean priors.
class AlignProblem {
 public:
  explicit AlignProblem(const AlignInput& in)
      : in_(in),
        w0_(1.0 / (in.sigma_xy * in.sigma_xy)),
        prior_ba_(1.0 / (in.sigma_ba_mps2 * in.sigma_ba_mps2)),
        prior_bg_(1.0 / (in.sigma_bg_radps * in.sigma_bg_radps)) {}

  double w0() const { return w0_; }

  double prior_cost(const VecX& x) const {
    return prior_ba_ * x.segment<3>(6).squaredNorm() + prior_bg_ * x.segment<3>(9).squaredNorm();
  }

  // Reprojection cost of x and P plus the priors; with drop, the tracks behind a camera or with an
  // observation further than outlier_xy are removed from *P_out.
  double cost(const VecX& x, const TrackPoints& P, bool drop, TrackPoints* P_out, std::size_t* obs) const {
    double c = 0.0;
    *obs = 0;
    for (std::size_t f = 0; f < in_.tracks.size(); ++f) {
      if (!P[f]) continue;
      double track = 0.0;
      bool bad = false;
      for (const auto& [k, xy] : in_.tracks[f]) {
        const Eigen::Matrix3d R_k = rotation(k, x);
        const Eigen::Vector3d pc =
            in_.R_b_c.transpose() *
            (R_k.transpose() * (*P[f] - imu_position(in_, k, x.head<9>())) - in_.p_b_c);
        if (pc.z() <= 1e-3) {
          bad = true;
          break;
        }
        const double e2 = (pc.head<2>() / pc.z() - xy).squaredNorm();
        bad = bad || e2 > in_.outlier_xy * in_.outlier_xy;
        track += e2;
      }
      if (bad && drop) {
        (*P_out)[f].reset();
        continue;
      }
      c += bad ? in_.outlier_xy * in_.outlier_xy * static_cast<double>(in_.tracks[f].size()) : track;
      *obs += in_.tracks[f].size();
    }
    return c * w0_ + prior_cost(x);
  }

  // The cost over every track given: the tracks without a position (dropped) count as outliers on each of
  // their observations, so that solutions which keep different tracks compare.
  double truncated_cost(const VecX& x, const TrackPoints& P) const {
    std::size_t obs = 0;
    double c = cost(x, P, false, nullptr, &obs);
    for (std::size_t f = 0; f < in_.tracks.size(); ++f) {
      if (!P[f]) c += w0_ * in_.outlier_xy * in_.outlier_xy * static_cast<double>(in_.tracks[f].size());
    }
    return c;
  }

  AlignStep linearise(const VecX& x, const TrackPoints& P) const {
    AlignStep s;
    const std::size_t nt = in_.tracks.size();
    s.Haa_inv.resize(nt);  // every entry empty: a fresh step
    s.Hab.resize(nt);
    s.ga.resize(nt);
    for (std::size_t f = 0; f < nt; ++f) {
      if (P[f]) add_track(f, x, *P[f], &s);
    }
    s.N.block<3, 3>(6, 6) += prior_ba_ * Eigen::Matrix3d::Identity();
    s.q.segment<3>(6) += prior_ba_ * x.segment<3>(6);
    s.N.block<3, 3>(9, 9) += prior_bg_ * Eigen::Matrix3d::Identity();
    s.q.segment<3>(9) += prior_bg_ * x.segment<3>(9);
    return s;
  }

  // Tangent parametrisation of gravity on its sphere: x = x0 + C dz.
  static MatXZ sphere_basis(const VecX& x) {
    MatXZ C = MatXZ::Zero();
    C.block<3, 3>(0, 0).setIdentity();
    C.block<3, 2>(3, 3) = tangent_basis(x.segment<3>(3).normalized());
    C.block<6, 6>(6, 5).setIdentity();
    return C;
  }

 private:
  Eigen::Matrix3d rotation(std::size_t k, const VecX& x) const {
    return Eigen::Matrix3d(in_.R_b0_bk[k] * so3_exp(in_.J_R_bg[k] * x.segment<3>(9)));
  }

  // The Jacobians of one observation (image k, normalised xy) of a track at p: A on the track's position
  // (minus A on the IMU's position at image k), B on x; e the reprojection error.
  void observation(std::size_t k, const Eigen::Vector2d& xy, const VecX& x, const Eigen::Vector3d& p,
                   Eigen::Matrix<double, 2, 3>* A, Eigen::Matrix<double, 2, kAlignDim>* B,
                   Eigen::Vector2d* e) const {
    const Eigen::Matrix3d R_k = rotation(k, x);
    const Eigen::Vector3d u = R_k.transpose() * (p - imu_position(in_, k, x.head<9>()));
    const Eigen::Vector3d pc = in_.R_b_c.transpose() * (u - in_.p_b_c);
    const double iz = 1.0 / std::max(pc.z(), 1e-3);
    Eigen::Matrix<double, 2, 3> Jpi;
    Jpi << iz, 0.0, -pc.x() * iz * iz, 0.0, iz, -pc.y() * iz * iz;
    *A = Jpi * in_.R_b_c.transpose() * R_k.transpose();
    const double T = in_.T_s[k];
    Eigen::Matrix<double, 3, 9> dp_dx;
    dp_dx << T * Eigen::Matrix3d::Identity(), 0.5 * T * T * Eigen::Matrix3d::Identity(), in_.J_alpha_ba[k];
    *B << -*A * dp_dx, Jpi * in_.R_b_c.transpose() * skew(u) * in_.J_R_bg[k];
    *e = pc.head<2>() * iz - xy;
  }

  // Track f's block of the normal equations, eliminated by its Schur complement (skipped without parallax).
  void add_track(std::size_t f, const VecX& x, const Eigen::Vector3d& p, AlignStep* s) const {
    Eigen::Matrix3d haa = Eigen::Matrix3d::Zero();
    Eigen::Matrix<double, 3, kAlignDim> hab = Eigen::Matrix<double, 3, kAlignDim>::Zero();
    MatX hbb = MatX::Zero();
    Eigen::Vector3d a_r = Eigen::Vector3d::Zero();
    VecX b_r = VecX::Zero();
    for (const auto& [k, xy] : in_.tracks[f]) {
      Eigen::Matrix<double, 2, 3> A;
      Eigen::Matrix<double, 2, kAlignDim> B;
      Eigen::Vector2d e;
      observation(k, xy, x, p, &A, &B, &e);
      haa += A.transpose() * A;
      hab += A.transpose() * B;
      hbb += B.transpose() * B;
      a_r += A.transpose() * e;
      b_r += B.transpose() * e;
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(haa);
    if (!(eig.eigenvalues()(0) > 1e-9 * eig.eigenvalues()(2))) return;
    const Eigen::Matrix3d inv = haa.inverse();
    s->Haa_inv[f] = inv;
    s->Hab[f] = hab;
    s->ga[f] = a_r;
    s->N += w0_ * (hbb - hab.transpose() * inv * hab);
    s->q += w0_ * (b_r - hab.transpose() * inv * a_r);
    ++s->active;
  }

 public:
  // The cross block of the normal equations between x and an error e_k of the pre-integrated IMU position
  // at each image k >= 1 (columns 3(k-1)..), the tracks of the step eliminated: x moves by -N^-1 H e.
  Eigen::MatrixXd imu_cross(const VecX& x, const TrackPoints& P, const AlignStep& s) const {
    const std::size_t n = in_.T_s.size();
    const auto cols = static_cast<Eigen::Index>(3 * (n - 1));
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(kAlignDim, cols);
    for (std::size_t f = 0; f < in_.tracks.size(); ++f) {
      if (!P[f] || !s.Haa_inv[f]) continue;
      Eigen::MatrixXd hae = Eigen::MatrixXd::Zero(3, cols);
      Eigen::MatrixXd hbe = Eigen::MatrixXd::Zero(kAlignDim, cols);
      for (const auto& [k, xy] : in_.tracks[f]) {
        if (k == 0) continue;  // the first image is the origin of the pre-integration: no error
        Eigen::Matrix<double, 2, 3> A;
        Eigen::Matrix<double, 2, kAlignDim> B;
        Eigen::Vector2d e;
        observation(k, xy, x, *P[f], &A, &B, &e);
        const auto c = static_cast<Eigen::Index>(3 * (k - 1));
        hae.block(0, c, 3, 3) -= A.transpose() * A;
        hbe.block(0, c, kAlignDim, 3) -= B.transpose() * A;
      }
      H += w0_ * (hbe - s.Hab[f].transpose() * *s.Haa_inv[f] * hae);
    }
    return H;
  }

 private:
  const AlignInput& in_;
  double w0_;
  double prior_ba_;
  double prior_bg_;
};

// Levenberg-Marquardt on x (gravity moved on its sphere) and P, from the linear guess. Tracks that are bad at
// the current estimate are dropped from the fourth iteration on (the guess is rough). False, with why, when
// fewer than 8 consistent tracks remain.
bool refine_alignment(const AlignProblem& problem, VecX* x, TrackPoints* P, double gravity_mps2,
                      std::string* why) {
  double lambda = 1e-3;
  std::size_t obs = 0;
  for (int it = 0; it < 30; ++it) {
    if (it >= 3) problem.cost(*x, *P, true, P, &obs);
    const AlignStep s = problem.linearise(*x, *P);
    if (s.active < 8) {
      *why = fmt("alignment: %zu consistent tracks < 8", s.active);
      return false;
    }
    const MatXZ C = AlignProblem::sphere_basis(*x);
    const MatZ Nz = C.transpose() * s.N * C;
    const VecZ qz = C.transpose() * s.q;
    const double c0 = problem.cost(*x, *P, false, nullptr, &obs);
    bool accepted = false;
    bool converged = false;
    for (int tries = 0; tries < 8 && !accepted; ++tries) {
      MatZ Nd = Nz;
      Nd.diagonal() *= 1.0 + lambda;
      const VecZ dz = -Nd.ldlt().solve(qz);
      const VecX dx = C * dz;
      VecX x_new = *x + dx;
      x_new.segment<3>(3) = x_new.segment<3>(3).normalized() * gravity_mps2;
      TrackPoints P_new = *P;
      for (std::size_t f = 0; f < P_new.size(); ++f) {
        if (P_new[f] && s.Haa_inv[f]) *P_new[f] -= *s.Haa_inv[f] * (s.ga[f] + s.Hab[f] * dx);
        if (P_new[f] && !s.Haa_inv[f]) P_new[f].reset();  // no parallax at this estimate
      }
      const double c1 = problem.cost(x_new, P_new, false, nullptr, &obs);
      if (c1 < c0) {
        converged = (c0 - c1) < 1e-9 * c0;
        *x = x_new;
        *P = std::move(P_new);
        lambda = std::max(lambda / 10.0, 1e-9);
        accepted = true;
      } else {
        lambda *= 10.0;
      }
    }
    if (!accepted || converged) break;
  }
  return true;
}

}  // namespace

// Gauss-Newton (Levenberg-Marquardt) on the reprojection errors themselves, from the linear guess. The
// unknowns are x = [v0, g, ba, dbg] - dbg a correction of the gyro bias that turns every rotation by
// Exp(J_k dbg) - with g moved only on its sphere, and every track's position (eliminated by its Schur
// complement); both biases are under their zero-mean priors. Tracks behind a camera or with an observation
// further than outlier_xy are dropped as the solve goes. One more step with gravity's norm free gives the
// |g| the data alone ask for: a check of the whole solve.
std::optional<AlignOutput> align_known_rotations(const AlignInput& in, std::string* why) {
  const std::size_t nt = in.tracks.size();
  Eigen::Matrix<double, 9, 1> x9;
  TrackPoints P;
  if (!linear_guess(in, &x9, &P, why)) return std::nullopt;
  VecX x = VecX::Zero();
  x.head<9>() = x9;
  const AlignProblem problem(in);
  // The reprojection cost is not convex in the scale: from the linear guess the solve can stop in a
  // minimum with the scene shrunk or stretched (on a car at nearly constant speed, 6.7 m/s where a lower
  // minimum lies at 10 m/s). It is therefore also started with the guess's velocity and scene scaled by
  // factors spread evenly in log scale over a factor of four, and the solution with the lowest cost over
  // all the tracks given wins (a dropped track counts as an outlier on each of its observations, so a
  // solution cannot win by dropping tracks).
  const TrackPoints P_guess = P;
  std::optional<double> best_cost;
  std::string why_first;
  for (std::size_t start = 0; start <= kAlignScaleStarts.size(); ++start) {
    const double factor = start == 0 ? 1.0 : kAlignScaleStarts[start - 1];
    VecX x_f = VecX::Zero();
    x_f.head<9>() = x9;
    x_f.segment<3>(0) *= factor;
    TrackPoints P_f = P_guess;
    for (std::optional<Eigen::Vector3d>& p : P_f) {
      if (p) *p *= factor;
    }
    std::string why_f;
    if (!refine_alignment(problem, &x_f, &P_f, in.gravity_mps2, &why_f)) {
      if (start == 0) why_first = why_f;
      continue;
    }
    const double cost_f = problem.truncated_cost(x_f, P_f);
    if (!best_cost || cost_f < *best_cost) {
      best_cost = cost_f;
      x = x_f;
      P = std::move(P_f);
    }
  }
  if (!best_cost) {
    *why = why_first;
    return std::nullopt;
  }
  std::size_t obs = 0;
  const double chi2 = problem.cost(x, P, true, &P, &obs);
  const AlignStep s = problem.linearise(x, P);
  if (s.active < 8) {  // the last outlier rejection can leave too few
    *why = fmt("alignment: %zu consistent tracks < 8", s.active);
    return std::nullopt;
  }
  // The tracks given are those the structure from motion found consistent with the rotations of vision:
  // the data the solution must explain. A solution that has to drop most of them as outliers is not the
  // data's solution but one a minority happens to fit (a shrunk scene with a near-zero velocity fits any
  // few tracks): refused.
  if (s.active < nt - s.active) {
    const std::size_t last = in.T_s.size() - 1;
    *why =
        fmt("alignment contradicts the structure: %zu tracks kept, %zu dropped as outliers (velocity at the "
            "first "
            "image %.2f m/s, IMU translation %.2f m)",
            s.active, nt - s.active, x.head<3>().norm(),
            (imu_position(in, last, x.head<9>()) - imu_position(in, 0, x.head<9>())).norm());
    return std::nullopt;
  }
  const MatXZ C = AlignProblem::sphere_basis(x);
  AlignOutput out;
  // One step with gravity's norm free, from the solution: the |g| the data alone ask for.
  const VecX dx_free = -s.N.ldlt().solve(s.q);
  out.g_norm_free = (x.segment<3>(3) + dx_free.segment<3>(3)).norm();
  out.x = x;
  out.tracks_used = s.active;
  out.tracks_dropped = nt - s.active;
  const double reproj2 = std::max(0.0, chi2 - problem.prior_cost(x)) / problem.w0();
  out.rms_xy = obs > 0 ? std::sqrt(reproj2 / static_cast<double>(2 * obs)) : 0.0;
  const double dof =
      std::max(1.0, static_cast<double>(2 * obs) - 3.0 * static_cast<double>(s.active) - (kAlignDim - 1.0));
  const MatZ Nz = C.transpose() * s.N * C;
  const MatZ Nz_inv = Nz.inverse();
  out.cov = C * (Nz_inv * std::max(1.0, chi2 / dof)) * C.transpose();
  out.cov_imu = out.cov;
  if (in.T_s.size() > 1 &&
      (in.accel_noise_density > 0.0 || in.gyro_noise_density > 0.0 || in.accel_random_walk > 0.0)) {
    const Eigen::MatrixXd D = C * Nz_inv * C.transpose() * problem.imu_cross(x, P, s);  // dx/de = -D
    out.cov_imu += D * preintegrated_position_covariance(in) * D.transpose();
    out.cov_imu = 0.5 * (out.cov_imu + out.cov_imu.transpose()).eval();
  }
  out.p_b0_bk.resize(in.T_s.size());
  for (std::size_t k = 0; k < in.T_s.size(); ++k) out.p_b0_bk[k] = imu_position(in, k, x.head<9>());
  return out;
}

Eigen::MatrixXd preintegrated_position_covariance(const AlignInput& in) {
  const std::size_t n = in.T_s.size();
  const auto dim = static_cast<Eigen::Index>(3 * (n > 0 ? n - 1 : 0));
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(dim, dim);
  const double qa = in.accel_noise_density * in.accel_noise_density;
  const double g_qg = in.gravity_mps2 * in.gravity_mps2 * in.gyro_noise_density * in.gyro_noise_density;
  const double qw = g_qg + in.accel_random_walk * in.accel_random_walk;
  // Three-point Gauss-Legendre on [0, m]: exact for the quartic (s-u)^2 (t-u)^2.
  const std::array<double, 3> node{-std::sqrt(0.6), 0.0, std::sqrt(0.6)};
  const std::array<double, 3> weight{5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  for (std::size_t i = 1; i < n; ++i) {
    for (std::size_t j = i; j < n; ++j) {
      const double m = std::min(in.T_s[i], in.T_s[j]);
      const double M = std::max(in.T_s[i], in.T_s[j]);
      double quartic = 0.0;
      for (std::size_t q = 0; q < 3; ++q) {
        const double u = 0.5 * m * (node[q] + 1.0);
        quartic += 0.5 * m * weight[q] * (m - u) * (m - u) * (M - u) * (M - u);
      }
      const double c = qa * (m * m * M / 2.0 - m * m * m / 6.0) + qw * quartic / 4.0;
      const auto r = static_cast<Eigen::Index>(3 * (i - 1));
      const auto k = static_cast<Eigen::Index>(3 * (j - 1));
      S.block(r, k, 3, 3) = c * Eigen::Matrix3d::Identity();
      S.block(k, r, 3, 3) = c * Eigen::Matrix3d::Identity();
    }
  }
  return S;
}

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
                                                     const EkfConfig& config) {
  const std::size_t n = in.T_s.size();
  const Eigen::Matrix3d R_w_bn = R_w * R_n;
  const Eigen::Matrix3d dphi_dg = skew(Eigen::Vector3d::UnitZ()) * R_w / in.gravity_mps2;
  Eigen::Matrix<double, 12, kAlignDim> J = Eigen::Matrix<double, 12, kAlignDim>::Zero();
  J.block<3, 3>(0, 3) = R_w_bn.transpose() * dphi_dg;
  J.block<3, 3>(0, 9) = in.J_R_bg[n - 1];
  J.block<3, 9>(3, 0) = R_w * J_vn;
  J.block<3, 3>(3, 3) -= skew(R_w * v_n) * dphi_dg;
  J.block<3, 3>(6, 9).setIdentity();
  J.block<3, 3>(9, 6).setIdentity();
  Eigen::Matrix<double, 12, 12> P = J * al.cov * J.transpose();
  const double tilt2 = std::pow(config.dynamic_init_min_sigma_tilt_rad, 2);
  const Eigen::Vector3d rot_floor_world(tilt2, tilt2, std::pow(config.init_sigma_yaw_rad, 2));
  P.block<3, 3>(0, 0) += R_w_bn.transpose() * rot_floor_world.asDiagonal() * R_w_bn;
  P.block<3, 3>(3, 3) += Eigen::Matrix3d::Identity() * std::pow(config.dynamic_init_min_sigma_vel_mps, 2);
  P.block<3, 3>(6, 6) +=
      Eigen::Matrix3d::Identity() * std::pow(config.dynamic_init_min_sigma_gyro_bias_radps, 2);
  return 0.5 * (P + P.transpose());
}

}  // namespace loopgate
