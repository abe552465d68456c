// ROS1 bag access (module bag, built only with LOOPGATE_WITH_ROSBAG): the one place that touches the ROS
// headers. Debian's generated message headers (sensor_msgs, std_msgs) do not compile as C++20 (they name
// std::allocator<void>::rebind, removed in C++20), so this module is built as C++17 and its interface holds
// only standard types: io/rosbag_dataset.cpp (C++20) turns what it reads into a Dataset.
//
// A BagReader indexes the messages of one image topic when asked (their header stamps and image geometry,
// read from the message headers; the pixels are not kept) and reads any of them again by its position on
// the topic, so that a gated run can re-read past frames in any order. Reading is serialised by a mutex
// (rosbag::Bag keeps one read buffer): every const method may be called from several threads at once.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace loopgate::bag {

// Thrown for every problem reading a bag; file() is the bag, message() says which topic and which message
// (its 0-based position on the topic) when one is concerned. what() reads "FILE: MESSAGE".
class BagError : public std::runtime_error {
 public:
  BagError(const std::string& file, const std::string& message);
  const std::string& file() const { return file_; }
  const std::string& message() const { return message_; }

 private:
  std::string file_;
  std::string message_;
};

struct TopicInfo {
  std::string name;
  std::string datatype;  // "sensor_msgs/Image", ...
  std::size_t messages = 0;
};

// What the header of an image message says (sensor_msgs/Image or sensor_msgs/CompressedImage).
struct ImageInfo {
  std::int64_t header_t_ns = 0;  // header.stamp
  std::int64_t bag_t_ns = 0;     // the time the message was recorded
  bool compressed = false;       // sensor_msgs/CompressedImage
  std::uint32_t width = 0;       // Image only (0 for CompressedImage)
  std::uint32_t height = 0;
  std::uint32_t step = 0;   // bytes per row
  std::string encoding;     // Image: encoding ("mono8", "bgr8", ...); CompressedImage: format ("jpeg", ...)
  bool big_endian = false;  // Image only
  std::size_t data_bytes = 0;
  std::string
      read_error;  // not empty: the message could not be read (truncated...), the fields above are unset
};

struct RawImage {
  ImageInfo info;
  std::vector<std::uint8_t> data;
};

struct ImuRecord {
  std::int64_t header_t_ns = 0;
  std::array<double, 3> angular_velocity_radps{};
  std::array<double, 3> linear_acceleration_mps2{};
  std::string read_error;  // not empty: the message could not be read, the fields above are unset
};

class BagReader {
 public:
  // Opens `file` and reads its index (not its messages). Throws BagError when it is not a readable bag.
  explicit BagReader(const std::string& file);
  ~BagReader();
  BagReader(const BagReader&) = delete;
  BagReader& operator=(const BagReader&) = delete;

  const std::string& file() const { return file_; }
  // Every topic of the bag, by name.
  const std::vector<TopicInfo>& topics() const { return topics_; }
  // "/cam0/image_raw (sensor_msgs/Image, 2273 messages), /imu0 (...)" for error messages.
  std::string topics_text() const;

  // Indexes the messages of `topic` in bag order and returns what their headers say (the image data is read
  // from the file, as every message record is, but not kept; a message that cannot be read has its read_error
  // set). Replaces the topic indexed before. Throws BagError when the topic is absent (listing the bag's
  // topics), is not of an image type, or has another definition of it (MD5 sum) than this build reads.
  std::vector<ImageInfo> index_images(const std::string& topic);
  // Message `message` (its position in index_images()) with its pixels.
  RawImage read_image(std::size_t message) const;

  // Every sensor_msgs/Imu message of `topic` in bag order (a message that cannot be read has its read_error
  // set). Throws BagError like index_images().
  std::vector<ImuRecord> read_imu(const std::string& topic) const;

 private:
  struct Impl;
  std::string file_;
  std::vector<TopicInfo> topics_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace loopgate::bag
