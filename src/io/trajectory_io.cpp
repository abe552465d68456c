#include "io/trajectory_io.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>

#include "core/error.hpp"
#include "io/csv_formats.hpp"
#include "io/csv_text.hpp"
#include "io/time_order.hpp"
#include "io/yaml_fields.hpp"

namespace loopgate {

namespace {

using io_detail::Delimiter;
using io_detail::is_rotation;
using io_detail::IssueLog;
using io_detail::keep_increasing;
using io_detail::load_yaml;
using io_detail::require_key;
using io_detail::rigid_transform;
using io_detail::Row;
using io_detail::RowError;
using io_detail::TextFile;
using io_detail::TimedRow;
using io_detail::yaml_line;
using io_detail::yaml_number;
using io_detail::yaml_numbers;

// A stored quaternion whose norm is further than this from 1 is rejected as garbage (rather than
// silently normalised); files carry 6+ decimals, so honest rounding is orders of magnitude smaller.
constexpr double kQuaternionNormTolerance = 1e-2;

constexpr int kKittiPoseColumns = 12;
constexpr int kKittiCameras = 4;
constexpr std::size_t kImuColumns = 7;
constexpr std::size_t kTumColumns = 8;

Eigen::Quaterniond checked_quaternion(double w, double x, double y, double z) {
  Eigen::Quaterniond q(w, x, y, z);
  const double norm = q.norm();
  if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
    throw RowError{"quaternion norm " + std::to_string(norm) + ", expected a unit quaternion"};
  }
  q.normalize();
  return q;
}

// ---------- KITTI calib ----------

Eigen::Matrix<double, 3, 4> kitti_row_matrix(const Row& row, std::size_t first_column, const char* name) {
  Eigen::Matrix<double, 3, 4> M;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      M(r, c) = row.number(first_column + static_cast<std::size_t>(4 * r + c), name);
    }
  }
  return M;
}

}  // namespace

// ====================== lenient-capable readers ======================

namespace io_detail {

std::vector<StampedPose> read_tum(const std::filesystem::path& file, IssueLog& log) {
  const TextFile text(file);
  std::vector<TimedRow<StampedPose>> rows;
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kWhitespace, log, [&](const Row& row) {
    row.expect_columns(kTumColumns, "t_s tx ty tz qx qy qz qw");
    StampedPose pose;
    pose.t_ns = row.seconds_ns(0, "t_s");
    const Eigen::Vector3d p(row.number(1, "tx"), row.number(2, "ty"), row.number(3, "tz"));
    const Eigen::Quaterniond q = checked_quaternion(row.number(7, "qw"), row.number(4, "qx"),
                                                    row.number(5, "qy"), row.number(6, "qz"));
    pose.T_w_b.linear() = q.toRotationMatrix();
    pose.T_w_b.translation() = p;
    rows.push_back({row.line, pose.t_ns, pose});
  });
  std::vector<StampedPose> poses;
  for (auto& row : keep_increasing(file, log, std::move(rows), "timestamp", true)) poses.push_back(row.value);
  log.end_table(file, lines);
  return poses;
}

namespace {
// EuRoC state_groundtruth_estimate0 and TUM-VI mocap0 tables: the first 8 columns are the same (t_ns, p_xyz,
// q_wxyz); `mocap` accepts those 8 only, the ground truth also its velocity and bias columns.
std::vector<GroundTruthState> read_groundtruth_csv(const std::filesystem::path& csv_file, IssueLog& log,
                                                   bool mocap) {
  const TextFile text(csv_file);
  std::vector<TimedRow<GroundTruthState>> rows;
  rows.reserve(text.text().size() / 160);
  std::size_t columns = 0;  // fixed by the first good row
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kComma, log, [&](const Row& row) {
    const std::size_t n = row.size();
    if (mocap && n != 8) {
      throw RowError{
          "expected 8 columns (timestamp [ns], p_RS_R_x, p_RS_R_y, p_RS_R_z [m], q_RS_w, q_RS_x, q_RS_y, "
          "q_RS_z) as in TUM-VI mocap0/data.csv, got " +
          std::to_string(n)};
    }
    if (columns == 0) {
      if (n != 8 && n != 11 && n != 14 && n != 17) {
        throw RowError{
            "expected 8, 11, 14 or 17 columns (t_ns, p_xyz, q_wxyz[, v_xyz, b_w_xyz, b_a_xyz]), got " +
            std::to_string(n)};
      }
    } else if (n != columns) {
      throw RowError{"expected " + std::to_string(columns) + " columns like the first data row, got " +
                     std::to_string(n)};
    }
    GroundTruthState s;
    s.t_ns = row.integer_ns(0, "timestamp [ns]");
    const Eigen::Vector3d p(row.number(1, "p_x"), row.number(2, "p_y"), row.number(3, "p_z"));
    const Eigen::Quaterniond q = checked_quaternion(row.number(4, "q_w"), row.number(5, "q_x"),
                                                    row.number(6, "q_y"), row.number(7, "q_z"));
    if (n >= 11)
      s.v_w_mps = Eigen::Vector3d(row.number(8, "v_x"), row.number(9, "v_y"), row.number(10, "v_z"));
    if (n >= 14) {
      s.gyro_bias_radps =
          Eigen::Vector3d(row.number(11, "b_w_x"), row.number(12, "b_w_y"), row.number(13, "b_w_z"));
    }
    if (n >= 17) {
      s.accel_bias_mps2 =
          Eigen::Vector3d(row.number(14, "b_a_x"), row.number(15, "b_a_y"), row.number(16, "b_a_z"));
    }
    s.T_w_b.linear() = q.toRotationMatrix();
    s.T_w_b.translation() = p;
    rows.push_back({row.line, s.t_ns, s});
    columns = n;
  });
  std::vector<GroundTruthState> states;
  states.reserve(rows.size());
  for (auto& row : keep_increasing(csv_file, log, std::move(rows), "ground-truth timestamp", false))
    states.push_back(row.value);
  log.end_table(csv_file, lines);
  return states;
}
}  // namespace

std::vector<GroundTruthState> read_euroc_groundtruth(const std::filesystem::path& csv_file, IssueLog& log) {
  return read_groundtruth_csv(csv_file, log, false);
}

std::vector<GroundTruthState> read_mocap_groundtruth(const std::filesystem::path& csv_file, IssueLog& log) {
  return read_groundtruth_csv(csv_file, log, true);
}

std::vector<EurocImageEntry> read_euroc_camera_csv(const std::filesystem::path& csv_file, IssueLog& log) {
  const TextFile text(csv_file);
  std::vector<TimedRow<EurocImageEntry>> rows;
  std::size_t data_rows = 0;
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kComma, log, [&](const Row& row) {
    const std::size_t index = data_rows++;  // the frame's number, kept through rejected rows
    row.expect_columns(2, "timestamp [ns], filename");
    EurocImageEntry entry;
    entry.t_ns = row.integer_ns(0, "timestamp [ns]");
    if (row.fields[1].empty()) throw RowError{"column 2 (filename): expected an image file name, got ''"};
    if (row.fields[1].find('/') != std::string_view::npos) {
      throw RowError{"column 2 (filename): expected a plain file name inside data/, got '" +
                     std::string(row.fields[1]) + "'"};
    }
    entry.filename = std::string(row.fields[1]);
    entry.index = index;
    rows.push_back({row.line, entry.t_ns, std::move(entry)});
  });
  std::vector<EurocImageEntry> images;
  images.reserve(rows.size());
  for (auto& row : keep_increasing(csv_file, log, std::move(rows), "camera timestamp", false))
    images.push_back(std::move(row.value));
  log.end_table(csv_file, lines);
  return images;
}

std::vector<ImuSample> read_euroc_imu(const std::filesystem::path& csv_file, IssueLog& log) {
  const TextFile text(csv_file);
  std::vector<TimedRow<ImuSample>> rows;
  rows.reserve(text.text().size() / 100);
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kComma, log, [&](const Row& row) {
    row.expect_columns(kImuColumns, "timestamp [ns], w_xyz [rad/s], a_xyz [m/s^2]");
    ImuSample s;
    s.t_ns = row.integer_ns(0, "timestamp [ns]");
    s.gyro_radps = Eigen::Vector3d(row.number(1, "w_x"), row.number(2, "w_y"), row.number(3, "w_z"));
    s.accel_mps2 = Eigen::Vector3d(row.number(4, "a_x"), row.number(5, "a_y"), row.number(6, "a_z"));
    rows.push_back({row.line, s.t_ns, s});
  });
  std::vector<ImuSample> samples;
  samples.reserve(rows.size());
  for (auto& row : keep_increasing(csv_file, log, std::move(rows), "IMU timestamp", false))
    samples.push_back(row.value);
  log.end_table(csv_file, lines);
  return samples;
}

std::vector<std::optional<Timestamp>> read_kitti_time_rows(const std::filesystem::path& times_file,
                                                           IssueLog& log) {
  const TextFile text(times_file);
  std::vector<std::optional<Timestamp>> rows;
  std::vector<TimedRow<std::size_t>> parsed;  // value: the row's index
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kWhitespace, log, [&](const Row& row) {
    rows.emplace_back();  // the row keeps its index even when bad
    row.expect_columns(1, "time in seconds");
    const Timestamp t_ns = row.seconds_ns(0, "t_s");
    parsed.push_back({row.line, t_ns, rows.size() - 1});
  });
  for (const auto& row : keep_increasing(times_file, log, std::move(parsed), "time", true))
    rows[row.value] = row.t_ns;
  log.end_table(times_file, lines);
  return rows;
}

std::vector<std::optional<KittiPoseRow>> read_kitti_pose_rows(const std::filesystem::path& poses_file,
                                                              IssueLog& log) {
  const TextFile text(poses_file);
  std::vector<std::optional<KittiPoseRow>> rows;
  std::vector<TimedRow<std::size_t>> timed;  // 13 columns: (line, time, row index), for the order check
  std::size_t columns = 0;                   // fixed by the first good row: 12 or 13
  log.begin_table();
  const std::size_t lines = for_each_row(text, Delimiter::kWhitespace, log, [&](const Row& row) {
    rows.emplace_back();  // the row keeps its index even when bad
    const std::size_t n = row.size();
    if (columns == 0 && n != kKittiPoseColumns && n != kKittiPoseColumns + 1) {
      throw RowError{"expected 12 columns (row-major 3x4 T_w_cam0) or 13 (time [s], then the 12), got " +
                     std::to_string(n)};
    }
    if (columns != 0 && n != columns) {
      throw RowError{"expected " + std::to_string(columns) + " columns like the first data row (" +
                     (columns == kKittiPoseColumns ? "no time" : "a time first") + "), got " +
                     std::to_string(n)};
    }
    const std::size_t first = n - kKittiPoseColumns;  // 1 when a time comes first
    KittiPoseRow pose;
    if (first == 1) pose.t_ns = row.seconds_ns(0, "t_s");
    const Eigen::Matrix<double, 3, 4> M = kitti_row_matrix(row, first, "pose");
    if (!is_rotation(M.leftCols<3>())) throw RowError{"rotation block is not a rotation matrix"};
    pose.T_w_cam0.linear() = M.leftCols<3>();
    pose.T_w_cam0.translation() = M.col(3);
    rows.back() = pose;
    columns = n;
    if (pose.t_ns) timed.push_back({row.line, *pose.t_ns, rows.size() - 1});
  });
  // Timed rows: the ones outside the longest strictly increasing run are bad (kept as nullopt).
  std::vector<char> in_order(rows.size(), 0);
  for (const auto& row : keep_increasing(poses_file, log, timed, "time", true)) in_order[row.value] = 1;
  for (const auto& row : timed) {
    if (!in_order[row.value]) rows[row.value].reset();
  }
  log.end_table(poses_file, lines);
  return rows;
}

}  // namespace io_detail

// ====================== public strict API ======================

std::vector<StampedPose> read_tum(const std::filesystem::path& file) {
  IssueLog log(true, nullptr);
  return io_detail::read_tum(file, log);
}

void write_tum(const std::filesystem::path& file, const std::vector<StampedPose>& poses) {
  std::string out = "# timestamp tx ty tz qx qy qz qw\n";
  out.reserve(poses.size() * 200);
  for (const StampedPose& pose : poses) {
    const Eigen::Quaterniond q(pose.T_w_b.linear());
    io_detail::append_seconds(out, pose.t_ns);
    const Eigen::Vector3d& p = pose.T_w_b.translation();
    for (const double v : {p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()}) {
      out += ' ';
      io_detail::append_double(out, v);
    }
    out += '\n';
  }
  io_detail::write_text_file(file, out);
}

std::vector<Timestamp> read_kitti_times(const std::filesystem::path& times_file) {
  IssueLog log(true, nullptr);
  std::vector<Timestamp> times;
  for (const auto& t : io_detail::read_kitti_time_rows(times_file, log)) times.push_back(*t);
  return times;
}

std::vector<StampedPose> read_kitti_poses(const std::filesystem::path& poses_file,
                                          const std::filesystem::path& times_file, bool allow_fewer) {
  IssueLog log(true, nullptr);
  const auto rows = io_detail::read_kitti_pose_rows(poses_file, log);
  if (!rows.empty() && rows.front()->t_ns) {  // 13 columns: every row has its own time
    std::vector<StampedPose> poses;
    poses.reserve(rows.size());
    for (const auto& row : rows) poses.push_back(StampedPose{*row->t_ns, row->T_w_cam0});
    return poses;
  }
  const auto times = io_detail::read_kitti_time_rows(times_file, log);
  if (rows.size() > times.size() || (!allow_fewer && rows.size() != times.size())) {
    throw DataError(poses_file, std::to_string(rows.size()) + " poses, expected " +
                                    (allow_fewer ? "at most " : "") + std::to_string(times.size()) +
                                    " (the rows of " + times_file.string() + ")");
  }
  std::vector<StampedPose> poses;
  poses.reserve(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) poses.push_back(StampedPose{*times[i], rows[i]->T_w_cam0});
  return poses;
}

std::vector<StampedPose> read_kitti_poses(const std::filesystem::path& poses_file,
                                          const std::filesystem::path& times_file) {
  return read_kitti_poses(poses_file, times_file, false);
}

CameraCalibration read_kitti_calib(const std::filesystem::path& calib_file, int camera_index) {
  if (camera_index < 0 || camera_index >= kKittiCameras) {
    throw DataError(calib_file, "camera index " + std::to_string(camera_index) + ", expected 0..3");
  }
  const TextFile text(calib_file);
  IssueLog log(true, nullptr);
  const std::string key = std::string("P").append(std::to_string(camera_index)).append(":");
  std::optional<Eigen::Matrix<double, 3, 4>> P;
  std::size_t line = 0;
  io_detail::for_each_row(text, Delimiter::kWhitespace, log, [&](const Row& row) {
    if (row.fields.front() != key) return;
    row.expect_columns(1 + kKittiPoseColumns, key + " and a row-major 3x4 projection matrix");
    P = kitti_row_matrix(row, 1, key.c_str());
    line = row.line;
  });
  if (!P)
    throw DataError(calib_file, "no line '" + key + "', expected the projection matrix of camera " +
                                    std::to_string(camera_index));
  const Eigen::Matrix3d K = P->leftCols<3>();
  if (!(K(0, 0) > 0) || !(K(1, 1) > 0) || K(1, 0) != 0 || K(2, 0) != 0 || K(2, 1) != 0 || K(2, 2) != 1) {
    throw DataError(calib_file, line,
                    key + " expected a rectified projection [fx 0 cx tx; 0 fy cy ty; 0 0 1 tz]");
  }
  CameraCalibration camera;
  camera.fx = K(0, 0);
  camera.fy = K(1, 1);
  camera.cx = K(0, 2);
  camera.cy = K(1, 2);
  // P_i = K [I | t_i] with x_ci = x_c0 + t_i, so camera i sits at -t_i in the camera-0 (body) frame.
  const Eigen::Vector3d t_ci_c0 = K.inverse() * P->col(3);
  camera.T_b_c = Eigen::Isometry3d::Identity();
  camera.T_b_c.translation() = -t_ci_c0;
  return camera;
}

void write_kitti_poses(const std::filesystem::path& poses_file,
                       const std::vector<Eigen::Isometry3d>& T_w_cam0) {
  std::string out;
  out.reserve(T_w_cam0.size() * 250);
  for (const Eigen::Isometry3d& T : T_w_cam0) {
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        if (r || c) out += ' ';
        io_detail::append_double(out, T.matrix()(r, c));
      }
    }
    out += '\n';
  }
  io_detail::write_text_file(poses_file, out);
}

void write_kitti_times(const std::filesystem::path& times_file, const std::vector<Timestamp>& t_ns) {
  std::string out;
  out.reserve(t_ns.size() * 24);
  for (const Timestamp t : t_ns) {
    io_detail::append_seconds(out, t);
    out += '\n';
  }
  io_detail::write_text_file(times_file, out);
}

std::vector<GroundTruthState> read_euroc_groundtruth(const std::filesystem::path& csv_file) {
  IssueLog log(true, nullptr);
  return io_detail::read_euroc_groundtruth(csv_file, log);
}

std::vector<ImuSample> read_euroc_imu(const std::filesystem::path& csv_file) {
  IssueLog log(true, nullptr);
  return io_detail::read_euroc_imu(csv_file, log);
}

std::vector<EurocImageEntry> read_euroc_camera_csv(const std::filesystem::path& csv_file) {
  IssueLog log(true, nullptr);
  return io_detail::read_euroc_camera_csv(csv_file, log);
}

std::vector<Timestamp> read_frame_times(const std::filesystem::path& file) {
  const io_detail::TextFile text(file);
  // A comma on the first data line: an EuRoC cam<i>/data.csv (t_ns, file name).
  const std::string_view all = text.text();
  for (std::size_t pos = 0; pos < all.size();) {
    const std::size_t end = std::min(all.find('\n', pos), all.size());
    const std::string_view line = all.substr(pos, end - pos);
    pos = end + 1;
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string_view::npos || line[first] == '#') continue;
    if (line.find(',') != std::string_view::npos) {
      std::vector<Timestamp> times;
      for (const EurocImageEntry& e : read_euroc_camera_csv(file)) times.push_back(e.t_ns);
      return times;
    }
    break;
  }
  // A plain list: one time per line, integer nanoseconds or decimal seconds, one unit for the whole file.
  constexpr Timestamp kMinStepNs = 1'000'000;  // 1 ms: simulation.frame_rate_hz is at most 1000 Hz
  IssueLog log(true, nullptr);
  std::vector<Timestamp> times;
  int seconds = -1;  // unknown / 0: nanoseconds / 1: seconds
  io_detail::for_each_row(text, io_detail::Delimiter::kWhitespace, log, [&](const io_detail::Row& row) {
    row.expect_columns(1, "one time per line (integer nanoseconds, or seconds with a decimal point)");
    const bool decimal = row.fields[0].find_first_of(".eE") != std::string_view::npos;
    if (seconds < 0) seconds = decimal ? 1 : 0;
    if (decimal != (seconds == 1)) {
      throw io_detail::RowError{std::string("expected ") +
                                (seconds == 1 ? "seconds with a decimal point" : "integer nanoseconds") +
                                " like the first time of the file, got '" + std::string(row.fields[0]) + "'"};
    }
    const Timestamp t_ns = decimal ? row.seconds_ns(0, "t_s") : row.integer_ns(0, "t_ns");
    if (!times.empty() && t_ns <= times.back()) {
      throw io_detail::RowError{"times must strictly increase (" + std::string(row.fields[0]) +
                                " is not after the previous time)"};
    }
    if (!times.empty() && t_ns - times.back() < kMinStepNs) {
      throw io_detail::RowError{
          "frames less than 1 ms apart (above 1000 Hz): integer times are nanoseconds; write seconds with a "
          "decimal point (" +
          std::string(row.fields[0]) + ".0)"};
    }
    times.push_back(t_ns);
  });
  if (times.empty()) throw DataError(file, "no times, expected one time per line");
  return times;
}

void write_euroc_camera_csv(const std::filesystem::path& csv_file,
                            const std::vector<EurocImageEntry>& images) {
  std::string out = "#timestamp [ns],filename\n";
  out.reserve(images.size() * 48);
  for (const EurocImageEntry& image : images) {
    io_detail::append_int(out, image.t_ns);
    out += ',';
    out += image.filename;
    out += '\n';
  }
  io_detail::write_text_file(csv_file, out);
}

void write_euroc_imu(const std::filesystem::path& csv_file, const std::vector<ImuSample>& samples) {
  std::string out =
      "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
      "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n";
  out.reserve(samples.size() * 140);
  for (const ImuSample& s : samples) {
    io_detail::append_int(out, s.t_ns);
    for (const double v : {s.gyro_radps.x(), s.gyro_radps.y(), s.gyro_radps.z(), s.accel_mps2.x(),
                           s.accel_mps2.y(), s.accel_mps2.z()}) {
      out += ',';
      io_detail::append_double(out, v);
    }
    out += '\n';
  }
  io_detail::write_text_file(csv_file, out);
}

void write_euroc_groundtruth(const std::filesystem::path& csv_file,
                             const std::vector<GroundTruthState>& states) {
  std::string out =
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
      "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad "
      "s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]\n";
  out.reserve(states.size() * 330);
  for (const GroundTruthState& s : states) {
    io_detail::append_int(out, s.t_ns);
    const Eigen::Quaterniond q(s.T_w_b.linear());
    const Eigen::Vector3d& p = s.T_w_b.translation();
    for (const double v : {p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z(), s.v_w_mps.x(), s.v_w_mps.y(),
                           s.v_w_mps.z(), s.gyro_bias_radps.x(), s.gyro_bias_radps.y(), s.gyro_bias_radps.z(),
                           s.accel_bias_mps2.x(), s.accel_bias_mps2.y(), s.accel_bias_mps2.z()}) {
      out += ',';
      io_detail::append_double(out, v);
    }
    out += '\n';
  }
  io_detail::write_text_file(csv_file, out);
}

}  // namespace loopgate
