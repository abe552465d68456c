// A 3-D pose graph in the g2o text format, the one g2o, GTSAM (readG2o) and Ceres' pose_graph_3d example
// read:
//   VERTEX_SE3:QUAT id tx ty tz qx qy qz qw        a node's pose T_w_b (here: its initial, odometry pose)
//   EDGE_SE3:QUAT a b tx ty tz qx qy qz qw I(21)   a relative pose T_a_b and the upper triangle of its 6x6
//                                                  information matrix, row by row
//   FIX id                                         a node held fixed (the gauge)
// loopgate writes the graph of its final solve as pose_graph.g2o: vertex ids are the frames' indices (those
// of frames.csv and loops.csv), the first node is fixed. The information matrix is that of loopgate's
// residual (stages/posegraph/pose_graph.cpp): [R_a^T (p_b - p_a) - t_ab; 2 vec(q_ab^-1 q_a^-1 q_b)], position
// first, rotation in radians (a right perturbation of the relative rotation) - the order and units GTSAM and
// Ceres' example take the file's numbers in. g2o's own EdgeSE3 measures the rotation by the quaternion's
// vector part (half the angle): its rotation block is four times this one's.
// Reading: '#' comments and blank lines skipped; every error is a DataError naming the file and line.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <vector>

namespace loopgate {

struct G2oVertex {
  std::int64_t id = 0;
  Eigen::Isometry3d T_w_b = Eigen::Isometry3d::Identity();
};

struct G2oEdge {
  std::int64_t a = 0, b = 0;
  Eigen::Isometry3d T_a_b = Eigen::Isometry3d::Identity();
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
};

struct G2oGraph {
  std::vector<G2oVertex> vertices;  // in file order
  std::vector<G2oEdge> edges;       // in file order
  std::vector<std::int64_t> fixed;  // ids of FIX lines
};

// Written whole or not at all (a temporary file renamed when complete). Numbers in shortest round-trip form.
// Throws DataError when the file cannot be written.
void write_g2o(const std::filesystem::path& file, const G2oGraph& graph);

// Throws DataError naming the file and line: an unknown tag, a wrong number of fields, a number that is not
// finite, a quaternion far from unit norm (|1 - |q|| > 1e-3; closer ones are normalised), a vertex id given
// twice, an edge or FIX naming a vertex the file does not define, an information matrix that is not
// symmetric positive definite.
G2oGraph read_g2o(const std::filesystem::path& file);

}  // namespace loopgate
