// The pose graph's edge residual (pose_graph.cpp), in a header of its own so that a test can check its
// closed-form Jacobians against automatic differentiation of the same expression.
#pragma once

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace loopgate {

// The residual r = sqrt_information * [R_a^T (p_b - p_a) - t_ab ; 2 vec(q_ab_measured^-1 q_a^-1 q_b)] as a
// functor of any scalar type (automatic differentiation needs one; the chi-square of an edge after a solve).
class RelativePoseResidual {
 public:
  RelativePoseResidual(const Eigen::Isometry3d& T_a_b, const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : t_a_b_(T_a_b.translation()), q_a_b_(T_a_b.rotation()), sqrt_information_(sqrt_information) {}

  template <class T>
  bool operator()(const T* p_a_ptr, const T* q_a_ptr, const T* p_b_ptr, const T* q_b_ptr, T* residual) const {
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_a(p_a_ptr), p_b(p_b_ptr);
    const Eigen::Map<const Eigen::Quaternion<T>> q_a(q_a_ptr), q_b(q_b_ptr);
    const Eigen::Quaternion<T> q_a_inverse = q_a.conjugate();
    const Eigen::Matrix<T, 3, 1> p_ab = q_a_inverse * (p_b - p_a);
    const Eigen::Quaternion<T> q_error = q_a_b_.template cast<T>().conjugate() * (q_a_inverse * q_b);
    Eigen::Map<Eigen::Matrix<T, 6, 1>> r(residual);
    r.template head<3>() = p_ab - t_a_b_.template cast<T>();
    r.template tail<3>() = T(2.0) * q_error.vec();
    r.applyOnTheLeft(sqrt_information_.template cast<T>());
    return true;
  }

  const Eigen::Quaterniond& q_a_b() const { return q_a_b_; }
  const Eigen::Matrix<double, 6, 6>& sqrt_information() const { return sqrt_information_; }

 private:
  Eigen::Vector3d t_a_b_;
  Eigen::Quaterniond q_a_b_;
  Eigen::Matrix<double, 6, 6> sqrt_information_;
};

// The same residual with its Jacobians in closed form (automatic differentiation of it took 40% of a final
// solve on KITTI 00). The quaternions are Eigen's (x, y, z, w) parameter blocks; the Jacobians are with
// respect to those four numbers as the expression uses them (Eigen rotates a vector by a quaternion assuming
// it is unit), as automatic differentiation gives them
// (PoseGraph.AnalyticJacobiansEqualAutomaticDifferentiation).
class RelativePoseCost : public ceres::SizedCostFunction<6, 3, 4, 3, 4> {
 public:
  RelativePoseCost(const Eigen::Isometry3d& T_a_b, const Eigen::Matrix<double, 6, 6>& sqrt_information)
      : residual_(T_a_b, sqrt_information) {}

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    residual_(parameters[0], parameters[1], parameters[2], parameters[3], residuals);
    const Eigen::Matrix<double, 6, 6>& S = residual_.sqrt_information();
    if (jacobians == nullptr) return true;
    const Eigen::Map<const Eigen::Vector3d> p_a(parameters[0]), p_b(parameters[2]);
    const Eigen::Map<const Eigen::Quaterniond> q_a(parameters[1]), q_b(parameters[3]);
    const Eigen::Vector3d d = p_b - p_a;
    const Eigen::Vector3d v = q_a.vec();
    const double w = q_a.w();
    // Eigen's q^-1 * d for q^-1 = (-v, w): d - 2 w (v x d) + 2 v x (v x d).
    const Eigen::Matrix3d V = skew(v);
    const Eigen::Matrix3d rotate = Eigen::Matrix3d::Identity() - 2.0 * w * V + 2.0 * V * V;  // d(p_ab)/dd
    Eigen::Matrix<double, 3, 4> dt_dqa;
    dt_dqa.leftCols<3>() = 2.0 * w * skew(d) + 2.0 * (v.dot(d) * Eigen::Matrix3d::Identity() +
                                                      v * d.transpose() - 2.0 * d * v.transpose());
    dt_dqa.col(3) = -2.0 * v.cross(d);
    // e = m* (a* b), bilinear: de/db = L(m* a*), de/da = L(m*) R(b) diag(-1, -1, -1, 1).
    const Eigen::Quaterniond m_conj = residual_.q_a_b().conjugate();
    const Eigen::Matrix4d de_dqb = left_product(m_conj * q_a.conjugate());
    Eigen::Matrix4d de_dqa = left_product(m_conj) * right_product(q_b);
    de_dqa.leftCols<3>() *= -1.0;
    using Block3 = Eigen::Matrix<double, 6, 3, Eigen::RowMajor>;
    using Block4 = Eigen::Matrix<double, 6, 4, Eigen::RowMajor>;
    if (jacobians[0] != nullptr) {
      Eigen::Map<Block3> J(jacobians[0]);
      J = S.leftCols<3>() * -rotate;
    }
    if (jacobians[1] != nullptr) {
      Block4 raw;
      raw.topRows<3>() = dt_dqa;
      raw.bottomRows<3>() = 2.0 * de_dqa.topRows<3>();
      Eigen::Map<Block4> J(jacobians[1]);
      J = S * raw;
    }
    if (jacobians[2] != nullptr) {
      Eigen::Map<Block3> J(jacobians[2]);
      J = S.leftCols<3>() * rotate;
    }
    if (jacobians[3] != nullptr) {
      Eigen::Map<Block4> J(jacobians[3]);
      J = S.rightCols<3>() * (2.0 * de_dqb.topRows<3>());
    }
    return true;
  }

 private:
  static Eigen::Matrix3d skew(const Eigen::Vector3d& x) {
    Eigen::Matrix3d m;
    m << 0.0, -x.z(), x.y(), x.z(), 0.0, -x.x(), -x.y(), x.x(), 0.0;
    return m;
  }
  // p q = left_product(p) q = right_product(q) p, on (x, y, z, w) coefficient vectors.
  static Eigen::Matrix4d left_product(const Eigen::Quaterniond& p) {
    Eigen::Matrix4d m;
    m.topLeftCorner<3, 3>() = p.w() * Eigen::Matrix3d::Identity() + skew(p.vec());
    m.topRightCorner<3, 1>() = p.vec();
    m.bottomLeftCorner<1, 3>() = -p.vec().transpose();
    m(3, 3) = p.w();
    return m;
  }
  static Eigen::Matrix4d right_product(const Eigen::Quaterniond& q) {
    Eigen::Matrix4d m;
    m.topLeftCorner<3, 3>() = q.w() * Eigen::Matrix3d::Identity() - skew(q.vec());
    m.topRightCorner<3, 1>() = q.vec();
    m.bottomLeftCorner<1, 3>() = -q.vec().transpose();
    m(3, 3) = q.w();
    return m;
  }

  RelativePoseResidual residual_;
};

}  // namespace loopgate
