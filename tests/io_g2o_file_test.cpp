// The g2o pose-graph file (io/g2o_file.hpp): what write_g2o writes read_g2o reads back exactly (poses,
// information, fixed vertices), in the layout other tools read; and every malformed line is refused with the
// file and line.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

#include "core/error.hpp"
#include "io/g2o_file.hpp"
#include "test_support.hpp"

namespace loopgate {
namespace {

namespace fs = std::filesystem;
using testing::catch_data_error;

Eigen::Isometry3d pose(double angle, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T.translation() = t;
  return T;
}

G2oGraph small_graph() {
  G2oGraph g;
  g.vertices = {
      {10, pose(0.0, {0, 0, 0})}, {11, pose(0.3, {1.0, 0.1, -0.2})}, {40, pose(2.9, {1.0 / 3, 7, 1e-9})}};
  g.fixed = {10};
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Random();
  g.edges.push_back({10, 11, g.vertices[0].T_w_b.inverse() * g.vertices[1].T_w_b,
                     A * A.transpose() + Eigen::Matrix<double, 6, 6>::Identity()});
  g.edges.push_back({11, 40, pose(-1.0, {0.5, 0.25, 3}), Eigen::Matrix<double, 6, 6>::Identity() * 400.0});
  return g;
}

fs::path write_text(const fs::path& file, const std::string& text) {
  fs::create_directories(file.parent_path());
  std::ofstream(file, std::ios::binary) << text;
  return file;
}

TEST(IoG2oFile, WhatIsWrittenReadsBackExactly) {
  const fs::path file = testing::make_temp_dir("g2o") / "graph.g2o";
  const G2oGraph g = small_graph();
  write_g2o(file, g);
  const G2oGraph r = read_g2o(file);
  ASSERT_EQ(r.vertices.size(), g.vertices.size());
  ASSERT_EQ(r.edges.size(), g.edges.size());
  EXPECT_EQ(r.fixed, g.fixed);
  for (std::size_t k = 0; k < g.vertices.size(); ++k) {
    EXPECT_EQ(r.vertices[k].id, g.vertices[k].id);
    EXPECT_TRUE(r.vertices[k].T_w_b.isApprox(g.vertices[k].T_w_b, 1e-14)) << k;
  }
  for (std::size_t k = 0; k < g.edges.size(); ++k) {
    EXPECT_EQ(r.edges[k].a, g.edges[k].a);
    EXPECT_EQ(r.edges[k].b, g.edges[k].b);
    EXPECT_TRUE(r.edges[k].T_a_b.isApprox(g.edges[k].T_a_b, 1e-14)) << k;
    // Shortest round-trip numbers: the symmetric information comes back bit for bit.
    EXPECT_EQ(r.edges[k].information, g.edges[k].information) << k;
  }
}

// The layout g2o, GTSAM and Ceres' example read: tag, ids, 7 pose numbers (quaternion x y z w, w >= 0), the
// 21 upper-triangle entries row by row.
TEST(IoG2oFile, LinesAreInTheStandardLayout) {
  const fs::path file = testing::make_temp_dir("g2o-layout") / "graph.g2o";
  G2oGraph g;
  g.vertices = {{0, Eigen::Isometry3d::Identity()}, {1, Eigen::Isometry3d::Identity()}};
  g.fixed = {0};
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(1, 2, 3);
  Eigen::Matrix<double, 6, 6> info = Eigen::Matrix<double, 6, 6>::Identity();
  info(0, 1) = info(1, 0) = 0.5;
  info(4, 5) = info(5, 4) = 0.25;
  info(5, 5) = 7;
  g.edges.push_back({0, 1, T, info});
  write_g2o(file, g);
  EXPECT_EQ(testing::read_file(file),
            "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
            "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n"
            "FIX 0\n"
            "EDGE_SE3:QUAT 0 1 1 2 3 0 0 0 1 1 0.5 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0.25 7\n");
  // A rotation whose Eigen quaternion has w < 0 is written with w >= 0 (the same rotation).
  g.vertices[1].T_w_b.linear() = Eigen::AngleAxisd(3.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  write_g2o(file, g);
  const G2oGraph r = read_g2o(file);
  EXPECT_TRUE(r.vertices[1].T_w_b.isApprox(g.vertices[1].T_w_b, 1e-14));
  std::istringstream lines(testing::read_file(file));
  std::string line;
  std::getline(lines, line);
  std::getline(lines, line);
  std::istringstream fields(line);
  std::string tag;
  double v[8];
  fields >> tag;
  for (double& x : v) fields >> x;
  EXPECT_GE(v[7], 0.0) << line;
}

TEST(IoG2oFile, CommentsAndBlankLinesAreSkipped) {
  const fs::path file = write_text(testing::make_temp_dir("g2o-comments") / "graph.g2o",
                                   "# a comment\n\nVERTEX_SE3:QUAT 3 1 2 3 0 0 0 1\n  # another\n");
  const G2oGraph r = read_g2o(file);
  ASSERT_EQ(r.vertices.size(), 1u);
  EXPECT_EQ(r.vertices[0].id, 3);
  EXPECT_TRUE(r.vertices[0].T_w_b.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
}

TEST(IoG2oFile, MalformedLinesNameTheFileAndLine) {
  const fs::path dir = testing::make_temp_dir("g2o-bad");
  const std::string v0 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n";
  const std::string v1 = "VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n";
  const std::string identity_info = " 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1\n";
  struct Case {
    std::string name, text;
    std::size_t line;
    std::string says;
  };
  const std::vector<Case> cases = {
      {"tag", v0 + "VERTEX_SE2 1 0 0 0\n", 2, "'VERTEX_SE2' is not read"},
      {"columns", v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 1\n", 2, "expected 9 columns"},
      {"number", v0 + "VERTEX_SE3:QUAT 1 0 x 0 0 0 0 1\n", 2, "expected a number"},
      {"nan", v0 + "VERTEX_SE3:QUAT 1 0 nan 0 0 0 0 1\n", 2, "finite"},
      {"id", "VERTEX_SE3:QUAT 1.5 0 0 0 0 0 0 1\n", 1, "integer vertex id"},
      {"quaternion", v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 2\n", 2, "norm"},
      {"twice", v0 + v1 + "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n", 3, "defined again (first on line 1)"},
      {"self", v0 + "EDGE_SE3:QUAT 0 0 1 0 0 0 0 0 1" + identity_info, 2, "to itself"},
      {"edge columns", v0 + v1 + "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 1 0 0\n", 3, "expected 31 columns"},
      {"not positive",
       v0 + v1 + "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 -1\n", 3,
       "not positive definite"},
      {"unknown vertex", v0 + "EDGE_SE3:QUAT 0 7 1 0 0 0 0 0 1" + identity_info, 2,
       "vertex 7 is not defined"},
      {"fix", v0 + "FIX 9\n", 2, "vertex 9 is not defined"},
      {"truncated", v0 + "VERTEX_SE3:QUAT 1 0 0", 2, "truncated"},
  };
  for (const Case& c : cases) {
    const fs::path file = write_text(dir / (c.name + ".g2o"), c.text);
    const DataError e = catch_data_error([&] { read_g2o(file); });
    EXPECT_EQ(e.file(), file) << c.name;
    EXPECT_EQ(e.line(), c.line) << c.name << ": " << e.what();
    EXPECT_NE(e.message().find(c.says), std::string::npos) << c.name << ": " << e.what();
  }
  EXPECT_NE(catch_data_error([&] { read_g2o(dir / "absent.g2o"); }).message().find("not found"),
            std::string::npos);
}

TEST(IoG2oFile, AWriteThatFailsLeavesNoFile) {
  const fs::path dir = testing::make_temp_dir("g2o-unwritable");
  const fs::path blocked = dir / "a-file";
  write_text(blocked, "x");
  // The parent "directory" is a file: the write fails with a DataError and no graph file appears.
  EXPECT_THROW(write_g2o(blocked / "graph.g2o", small_graph()), DataError);
  EXPECT_FALSE(fs::exists(blocked / "graph.g2o"));
}

}  // namespace
}  // namespace loopgate
