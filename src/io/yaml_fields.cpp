#include "io/yaml_fields.hpp"

#include <spdlog/fmt/fmt.h>

#include <charconv>
#include <cmath>
#include <string_view>

#include "core/error.hpp"
#include "io/csv_text.hpp"

namespace loopgate::io_detail {

namespace {
// Largest |R^T R - I| entry accepted for a rotation read as a matrix (KITTI poses, T_BS, T_cam_imu).
constexpr double kRotationOrthonormalTolerance = 1e-2;
// Largest deviation of the bottom row of a 4x4 transform from [0 0 0 1].
constexpr double kHomogeneousRowTolerance = 1e-9;
}  // namespace

YAML::Node load_yaml(const std::filesystem::path& file) {
  const TextFile text(file);
  std::string cleaned;
  cleaned.reserve(text.text().size());
  std::size_t pos = 0;
  const std::string& s = text.text();
  while (pos < s.size()) {
    std::size_t end = s.find('\n', pos);
    if (end == std::string::npos) end = s.size();
    std::string_view line(s.data() + pos, end - pos);
    if (!line.empty() && line.front() == '%') {
      cleaned += '#';
      cleaned.append(line.substr(1));
    } else {
      cleaned.append(line);
    }
    cleaned += '\n';
    pos = end + 1;
  }
  try {
    YAML::Node root = YAML::Load(cleaned);
    if (!root.IsMap()) throw DataError(file, "expected a YAML mapping of sensor keys");
    return root;
  } catch (const YAML::Exception& e) {
    throw DataError(file, static_cast<std::size_t>(e.mark.line + 1), "malformed YAML: " + e.msg);
  }
}

std::size_t yaml_line(const YAML::Node& node) {
  return static_cast<std::size_t>(node.Mark().line + 1);
}

YAML::Node require_key(const std::filesystem::path& file, const YAML::Node& root, const char* key) {
  const YAML::Node node = root[key];
  if (!node) throw DataError(file, std::string("missing key '") + key + "'");
  return node;
}

double yaml_number(const std::filesystem::path& file, const YAML::Node& node, const std::string& what) {
  if (!node.IsScalar()) throw DataError(file, yaml_line(node), what + ": expected a number");
  std::string_view text = node.Scalar();
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  double value = 0;
  const auto [ptr, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (text.empty() || ec != std::errc{} || ptr != text.data() + text.size() || !std::isfinite(value)) {
    throw DataError(file, yaml_line(node),
                    what + ": expected a finite number, got " + quote_excerpt(node.Scalar()));
  }
  return value;
}

std::vector<double> yaml_numbers(const std::filesystem::path& file, const YAML::Node& node,
                                 const std::string& what, std::size_t expected) {
  if (!node.IsSequence() || node.size() != expected) {
    throw DataError(file, yaml_line(node),
                    what + ": expected a list of " + std::to_string(expected) + " numbers");
  }
  std::vector<double> values;
  values.reserve(expected);
  for (std::size_t i = 0; i < expected; ++i) {
    values.push_back(yaml_number(file, node[i], what + "[" + std::to_string(i) + "]"));
  }
  return values;
}

bool is_rotation(const Eigen::Matrix3d& R) {
  return ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <=
          kRotationOrthonormalTolerance) &&
         R.determinant() > 0;
}

Eigen::Isometry3d rigid_transform(const std::filesystem::path& file, std::size_t line,
                                  const Eigen::Matrix4d& M, const std::string& what) {
  if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kHomogeneousRowTolerance) {
    throw DataError(file, line, what + ": expected bottom row [0, 0, 0, 1]");
  }
  if (!is_rotation(M.topLeftCorner<3, 3>())) {
    throw DataError(file, line, what + ": rotation block is not a rotation matrix");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = M.topLeftCorner<3, 3>();
  T.translation() = M.topRightCorner<3, 1>();
  return T;
}

DistortionModel yaml_distortion_model(const std::filesystem::path& file, const YAML::Node& node) {
  const std::string name = node && node.IsScalar() ? node.Scalar() : std::string("none");
  if (name == "radial-tangential" || name == "radtan") return DistortionModel::kRadTan;
  if (name == "equidistant") return DistortionModel::kEquidistant;
  if (name == "none") return DistortionModel::kNone;
  throw DataError(file, node ? yaml_line(node) : 0,
                  "distortion_model: " + quote_excerpt(name) +
                      ", expected radial-tangential (radtan), equidistant or none");
}

void yaml_resolution(const std::filesystem::path& file, const YAML::Node& node, CameraCalibration& camera) {
  const std::vector<double> size = yaml_numbers(file, node, "resolution [width, height]", 2);
  if (size[0] < 1 || size[1] < 1 || size[0] != std::floor(size[0]) || size[1] != std::floor(size[1])) {
    throw DataError(file, yaml_line(node), "resolution: expected two positive integers [width, height]");
  }
  // A bound before the cast to int (beyond it the cast is undefined: 1e12 read as -2147483648).
  constexpr double kMaxSidePx = 100000;
  if (size[0] > kMaxSidePx || size[1] > kMaxSidePx) {
    throw DataError(file, yaml_line(node),
                    fmt::format("resolution: [{}, {}] px, expected sides of at most {} px", size[0], size[1],
                                kMaxSidePx));
  }
  camera.width_px = static_cast<int>(size[0]);
  camera.height_px = static_cast<int>(size[1]);
}

void yaml_pinhole_intrinsics(const std::filesystem::path& file, const YAML::Node& node,
                             CameraCalibration& camera) {
  const std::vector<double> k = yaml_numbers(file, node, "intrinsics [fu, fv, cu, cv]", 4);
  if (!(k[0] > 0) || !(k[1] > 0)) {
    throw DataError(file, yaml_line(node), "intrinsics: expected positive focal lengths fu, fv");
  }
  camera.fx = k[0];
  camera.fy = k[1];
  camera.cx = k[2];
  camera.cy = k[3];
}

void yaml_distortion_coefficients(const std::filesystem::path& file, const YAML::Node& node, const char* key,
                                  CameraCalibration& camera) {
  const char* names =
      camera.distortion_model == DistortionModel::kRadTan ? " [k1, k2, p1, p2]" : " [k1, k2, k3, k4]";
  camera.distortion = yaml_numbers(file, node, std::string(key) + names, 4);
}

}  // namespace loopgate::io_detail
