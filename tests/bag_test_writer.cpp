// C++17 (see bag_test_writer.hpp).
#include "bag_test_writer.hpp"

#include <stdexcept>

#if LOOPGATE_WITH_ROSBAG
#include <rosbag/bag.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/Temperature.h>
#endif

namespace loopgate::testing {

#if LOOPGATE_WITH_ROSBAG

namespace {

ros::Time to_time(std::int64_t t_ns) {
  ros::Time t;
  t.fromNSec(static_cast<std::uint64_t>(t_ns));
  return t;
}

// When a message stamped t_ns arrives at the recorder.
constexpr std::int64_t kArrivalDelayNs = 1'000'000;
ros::Time recorded(std::int64_t t_ns) {
  return to_time(t_ns + kArrivalDelayNs);
}

}  // namespace

struct BagTestWriter::Impl {
  rosbag::Bag bag;
  std::uint32_t seq = 0;
};

BagTestWriter::BagTestWriter(const std::string& file, const std::string& compression)
    : impl_(std::make_unique<Impl>()) {
  impl_->bag.open(file, rosbag::bagmode::Write);
  if (compression == "lz4") {
    impl_->bag.setCompression(rosbag::compression::LZ4);
  } else if (compression == "bz2") {
    impl_->bag.setCompression(rosbag::compression::BZ2);
  } else if (compression != "none") {
    throw std::invalid_argument("compression: " + compression + ", expected none, lz4 or bz2");
  }
}

BagTestWriter::~BagTestWriter() = default;

void BagTestWriter::image(const std::string& topic, std::int64_t t_ns, std::uint32_t width,
                          std::uint32_t height, const std::string& encoding, std::uint32_t step,
                          const std::vector<std::uint8_t>& data, std::int64_t bag_t_ns) {
  sensor_msgs::Image m;
  m.header.seq = impl_->seq++;
  m.header.stamp = to_time(t_ns);
  m.header.frame_id = "cam0";
  m.width = width;
  m.height = height;
  m.encoding = encoding;
  m.step = step;
  m.data = data;
  impl_->bag.write(topic, bag_t_ns >= 0 ? to_time(bag_t_ns) : recorded(t_ns), m);
}

void BagTestWriter::compressed_image(const std::string& topic, std::int64_t t_ns, const std::string& format,
                                     const std::vector<std::uint8_t>& data) {
  sensor_msgs::CompressedImage m;
  m.header.seq = impl_->seq++;
  m.header.stamp = to_time(t_ns);
  m.header.frame_id = "cam0";
  m.format = format;
  m.data = data;
  impl_->bag.write(topic, recorded(t_ns), m);
}

void BagTestWriter::imu(const std::string& topic, std::int64_t t_ns, const std::array<double, 3>& w,
                        const std::array<double, 3>& a) {
  sensor_msgs::Imu m;
  m.header.seq = impl_->seq++;
  m.header.stamp = to_time(t_ns);
  m.header.frame_id = "imu4";
  m.angular_velocity.x = w[0];
  m.angular_velocity.y = w[1];
  m.angular_velocity.z = w[2];
  m.linear_acceleration.x = a[0];
  m.linear_acceleration.y = a[1];
  m.linear_acceleration.z = a[2];
  impl_->bag.write(topic, recorded(t_ns), m);
}

void BagTestWriter::temperature(const std::string& topic, std::int64_t t_ns, double celsius) {
  sensor_msgs::Temperature m;
  m.header.stamp = to_time(t_ns);
  m.temperature = celsius;
  impl_->bag.write(topic, recorded(t_ns), m);
}

void BagTestWriter::close() {
  impl_->bag.close();
}

#else

struct BagTestWriter::Impl {};

BagTestWriter::BagTestWriter(const std::string& file, const std::string&) {
  throw std::runtime_error(file + ": this build has no ROS1 bag support (LOOPGATE_WITH_ROSBAG=OFF)");
}
BagTestWriter::~BagTestWriter() = default;
void BagTestWriter::image(const std::string&, std::int64_t, std::uint32_t, std::uint32_t, const std::string&,
                          std::uint32_t, const std::vector<std::uint8_t>&, std::int64_t) {}
void BagTestWriter::compressed_image(const std::string&, std::int64_t, const std::string&,
                                     const std::vector<std::uint8_t>&) {}
void BagTestWriter::imu(const std::string&, std::int64_t, const std::array<double, 3>&,
                        const std::array<double, 3>&) {}
void BagTestWriter::temperature(const std::string&, std::int64_t, double) {}
void BagTestWriter::close() {}

#endif

}  // namespace loopgate::testing
