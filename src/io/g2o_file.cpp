#include "io/g2o_file.hpp"

#include <Eigen/Cholesky>
#include <charconv>
#include <cmath>
#include <map>
#include <string>
#include <string_view>

#include "core/error.hpp"
#include "io/csv_text.hpp"

namespace loopgate {

namespace {

using io_detail::Row;
using io_detail::RowError;

constexpr std::string_view kVertex = "VERTEX_SE3:QUAT";
constexpr std::string_view kEdge = "EDGE_SE3:QUAT";
constexpr std::string_view kFix = "FIX";

void append_pose(std::string& out, const Eigen::Isometry3d& T) {
  Eigen::Quaterniond q(T.rotation());
  if (q.w() < 0) q.coeffs() = -q.coeffs();  // one of the two quaternions of a rotation, w >= 0
  const Eigen::Vector3d t = T.translation();
  for (const double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) {
    out.push_back(' ');
    io_detail::append_double(out, v);
  }
}

std::int64_t vertex_id(const Row& row, std::size_t column, std::string_view name) {
  const std::string_view field = row.fields.at(column);
  std::int64_t id = 0;
  const auto [ptr, ec] = std::from_chars(field.data(), field.data() + field.size(), id);
  if (ec != std::errc{} || ptr != field.data() + field.size())
    throw RowError{"field " + std::to_string(column + 1) + " (" + std::string(name) +
                   "): expected an integer vertex id, got '" + std::string(field) + "'"};
  return id;
}

// tx ty tz qx qy qz qw from fields [first, first + 7).
Eigen::Isometry3d pose(const Row& row, std::size_t first) {
  static constexpr std::string_view kNames[] = {"tx", "ty", "tz", "qx", "qy", "qz", "qw"};
  double v[7];
  for (std::size_t k = 0; k < 7; ++k) v[k] = row.number(first + k, kNames[k]);
  Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
  const double norm = q.norm();
  if (std::abs(norm - 1.0) > 1e-3)
    throw RowError{"the quaternion (qx qy qz qw) has norm " + std::to_string(norm) + ", expected 1"};
  q.normalize();
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  return T;
}

}  // namespace

void write_g2o(const std::filesystem::path& file, const G2oGraph& graph) {
  std::string out;
  out.reserve(64 * graph.vertices.size() + 400 * graph.edges.size());
  for (const G2oVertex& v : graph.vertices) {
    out += kVertex;
    out.push_back(' ');
    io_detail::append_int(out, v.id);
    append_pose(out, v.T_w_b);
    out.push_back('\n');
  }
  for (const std::int64_t id : graph.fixed) {
    out += kFix;
    out.push_back(' ');
    io_detail::append_int(out, id);
    out.push_back('\n');
  }
  for (const G2oEdge& e : graph.edges) {
    out += kEdge;
    for (const std::int64_t id : {e.a, e.b}) {
      out.push_back(' ');
      io_detail::append_int(out, id);
    }
    append_pose(out, e.T_a_b);
    for (int r = 0; r < 6; ++r) {
      for (int c = r; c < 6; ++c) {
        out.push_back(' ');
        io_detail::append_double(out, 0.5 * (e.information(r, c) + e.information(c, r)));
      }
    }
    out.push_back('\n');
  }
  io_detail::write_text_file(file, out);
}

G2oGraph read_g2o(const std::filesystem::path& file) {
  const io_detail::TextFile text(file);
  io_detail::IssueLog log(true, nullptr);
  G2oGraph graph;
  std::map<std::int64_t, std::size_t> line_of_vertex;
  struct Reference {
    std::int64_t id;
    std::size_t line;
  };
  std::vector<Reference> references;  // vertex ids named by edges and FIX lines, checked at the end
  io_detail::for_each_row(text, io_detail::Delimiter::kWhitespace, log, [&](const Row& row) {
    const std::string_view tag = row.fields.at(0);
    if (tag == kVertex) {
      row.expect_columns(9, "VERTEX_SE3:QUAT id tx ty tz qx qy qz qw");
      G2oVertex v{vertex_id(row, 1, "id"), pose(row, 2)};
      const auto [it, inserted] = line_of_vertex.emplace(v.id, row.line);
      if (!inserted)
        throw RowError{"vertex " + std::to_string(v.id) + " is defined again (first on line " +
                       std::to_string(it->second) + ")"};
      graph.vertices.push_back(v);
    } else if (tag == kEdge) {
      row.expect_columns(31,
                         "EDGE_SE3:QUAT a b tx ty tz qx qy qz qw and the 21 upper-triangle entries of the "
                         "6x6 information matrix");
      G2oEdge e;
      e.a = vertex_id(row, 1, "a");
      e.b = vertex_id(row, 2, "b");
      if (e.a == e.b) throw RowError{"the edge joins vertex " + std::to_string(e.a) + " to itself"};
      e.T_a_b = pose(row, 3);
      std::size_t column = 10;
      for (int r = 0; r < 6; ++r) {
        for (int c = r; c < 6; ++c) {
          e.information(r, c) = e.information(c, r) = row.number(column++, "information");
        }
      }
      const Eigen::LLT<Eigen::Matrix<double, 6, 6>> llt(e.information);
      if (llt.info() != Eigen::Success) throw RowError{"the information matrix is not positive definite"};
      references.push_back({e.a, row.line});
      references.push_back({e.b, row.line});
      graph.edges.push_back(e);
    } else if (tag == kFix) {
      row.expect_columns(2, "FIX id");
      graph.fixed.push_back(vertex_id(row, 1, "id"));
      references.push_back({graph.fixed.back(), row.line});
    } else {
      throw RowError{"'" + std::string(tag) +
                     "' is not read: loopgate reads 3-D pose graphs (VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX)"};
    }
  });
  for (const Reference& r : references) {
    if (!line_of_vertex.count(r.id))
      throw DataError(file, r.line,
                      "vertex " + std::to_string(r.id) + " is not defined by a VERTEX_SE3:QUAT line");
  }
  return graph;
}

}  // namespace loopgate
