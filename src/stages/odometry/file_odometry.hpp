// The `file` odometry source: an external trajectory (io/trajectory_file.hpp) interpolated to each frame time
// (linear position, slerp rotation), with covariance from the growth model
//   position sigma^2 = a + b * d,   rotation sigma^2 = a_rot + b_rot * d   (isotropic),
// d the distance travelled along the trajectory up to the frame time.
#pragma once

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
  OdometryConfig config_;
  std::vector<StampedPose> poses_;
  std::vector<double> cumulative_m_;
  std::optional<double> previous_d_m_;  // distance at the previous tracked pose (step_cov)
};

}  // namespace loopgate
