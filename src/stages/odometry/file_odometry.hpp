// The `file` odometry source: an external trajectory (io/trajectory_file.hpp) interpolated to each frame time
// (linear position, slerp rotation), with covariance from the growth model
//   position sigma^2 = a + b * d,   rotation sigma^2 = a_rot + b_rot * d   (isotropic),
// d the distance travelled along the trajectory up to the frame time.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <vector>

#include "stages/odometry/odometry_source.hpp"

namespace loopgate {

class FileOdometry : public OdometrySource {
 public:
  // `poses` strictly increasing in time (read_trajectory_file guarantees it); throws std::invalid_argument if
  // empty.
  FileOdometry(const OdometryConfig& config, std::vector<StampedPose> poses);

  const char* name() const override { return "file"; }
  OdometryOutput process(const OdometryInput& input) override;

  // Distance travelled along the trajectory at t_ns (clamped to its span).
  double distance_at(Timestamp t_ns) const;

 private:
  // A pose of the trajectory as its time and the top three rows of its matrix (104 bytes instead of the 136
  // of a StampedPose, kept for every pose of the file for the whole run): an isometry's last row is
  // (0 0 0 1), so pose() gives back the same pose.
  struct FilePose {
    Timestamp t_ns = 0;
    Eigen::Matrix<double, 3, 4> top_rows;
    StampedPose pose() const;
  };

  OdometryConfig config_;
  std::vector<FilePose> poses_;
  std::vector<double> cumulative_m_;
  std::optional<double> previous_d_m_;  // distance at the previous tracked pose (step_cov)
};

}  // namespace loopgate
