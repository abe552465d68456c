// Writes ROS1 bags for the tests (tests/bag_test_writer.cpp, built as C++17 like src/bag because it includes
// the ROS1 message headers). In a build without ROS1 bag support (LOOPGATE_WITH_ROSBAG=OFF) the constructor
// throws std::runtime_error: tests start with LOOPGATE_REQUIRE_ROSBAG(), which skips them then.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace loopgate::testing {

class BagTestWriter {
 public:
  // compression: "none", "lz4" or "bz2" (the chunks of the bag).
  explicit BagTestWriter(const std::string& file, const std::string& compression = "none");
  ~BagTestWriter();
  BagTestWriter(const BagTestWriter&) = delete;
  BagTestWriter& operator=(const BagTestWriter&) = delete;

  // One message each, header.stamp = t_ns, recorded 1 ms later (bag time t_ns + 1 ms, unless bag_t_ns >= 0; a
  // bag time must be above 0, a stamp may be 0 like the simulator's first frame).
  void image(const std::string& topic, std::int64_t t_ns, std::uint32_t width, std::uint32_t height,
             const std::string& encoding, std::uint32_t step, const std::vector<std::uint8_t>& data,
             std::int64_t bag_t_ns = -1);
  void compressed_image(const std::string& topic, std::int64_t t_ns, const std::string& format,
                        const std::vector<std::uint8_t>& data);
  void imu(const std::string& topic, std::int64_t t_ns, const std::array<double, 3>& angular_velocity_radps,
           const std::array<double, 3>& linear_acceleration_mps2);
  // Any other message type, for the tests of a topic of the wrong type: a sensor_msgs/Temperature.
  void temperature(const std::string& topic, std::int64_t t_ns, double celsius);
  // Writes the index and closes the file (the destructor does it too).
  void close();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace loopgate::testing

// GTEST_SKIP with the reason in a build without bag support (needs io/dataset.hpp: rosbag_support_built()).
#define LOOPGATE_REQUIRE_ROSBAG()                                                                          \
  do {                                                                                                     \
    if (!::loopgate::rosbag_support_built()) {                                                             \
      GTEST_SKIP() << "this build has no ROS1 bag support (LOOPGATE_WITH_ROSBAG=OFF, the default without " \
                      "librosbag-storage-dev and libsensor-msgs-dev; scripts/setup.sh installs them)";     \
    }                                                                                                      \
  } while (0)
