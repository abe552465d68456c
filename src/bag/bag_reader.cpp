// C++17: includes the ROS1 message headers (see bag_reader.hpp).
#include "bag/bag_reader.hpp"

#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/Imu.h>

#include <algorithm>
#include <exception>
#include <mutex>
#include <set>
#include <utility>

#include "bag/bag_structure.hpp"

namespace loopgate::bag {
namespace {

// The fields of an image message before its pixels, read without copying them (indexing a bag reads every
// message record from the file anyway; this keeps the pixels out of memory). The byte layout is that of the
// ROS1 serialisation of sensor_msgs/Image and sensor_msgs/CompressedImage; the MD5 sums below make rosbag
// refuse a connection whose message definition differs.
struct ImageHeaderOnly {
  ImageInfo info;
};
struct CompressedHeaderOnly {
  ImageInfo info;
};

}  // namespace
}  // namespace loopgate::bag

namespace ros {
namespace message_traits {

template <>
struct MD5Sum<loopgate::bag::ImageHeaderOnly> {
  static const char* value() { return MD5Sum<sensor_msgs::Image>::value(); }
  static const char* value(const loopgate::bag::ImageHeaderOnly&) { return value(); }
};
template <>
struct DataType<loopgate::bag::ImageHeaderOnly> {
  static const char* value() { return DataType<sensor_msgs::Image>::value(); }
  static const char* value(const loopgate::bag::ImageHeaderOnly&) { return value(); }
};
template <>
struct MD5Sum<loopgate::bag::CompressedHeaderOnly> {
  static const char* value() { return MD5Sum<sensor_msgs::CompressedImage>::value(); }
  static const char* value(const loopgate::bag::CompressedHeaderOnly&) { return value(); }
};
template <>
struct DataType<loopgate::bag::CompressedHeaderOnly> {
  static const char* value() { return DataType<sensor_msgs::CompressedImage>::value(); }
  static const char* value(const loopgate::bag::CompressedHeaderOnly&) { return value(); }
};

}  // namespace message_traits

namespace serialization {

// std_msgs/Header: uint32 seq, time stamp (uint32 sec, uint32 nsec), string frame_id.
template <typename Stream>
void read_header(Stream& stream, loopgate::bag::ImageInfo& info) {
  std::uint32_t seq = 0, sec = 0, nsec = 0;
  std::string frame_id;
  stream.next(seq);
  stream.next(sec);
  stream.next(nsec);
  stream.next(frame_id);
  info.header_t_ns = static_cast<std::int64_t>(sec) * 1000000000 + static_cast<std::int64_t>(nsec);
}

// uint8[] data: uint32 length, then the bytes (skipped; a length beyond the message throws).
template <typename Stream>
void skip_data(Stream& stream, loopgate::bag::ImageInfo& info) {
  std::uint32_t bytes = 0;
  stream.next(bytes);
  stream.advance(bytes);
  info.data_bytes = bytes;
}

template <>
struct Serializer<loopgate::bag::ImageHeaderOnly> {
  // sensor_msgs/Image: Header header, uint32 height, uint32 width, string encoding, uint8 is_bigendian,
  // uint32 step, uint8[] data.
  template <typename Stream>
  static void read(Stream& stream, loopgate::bag::ImageHeaderOnly& m) {
    read_header(stream, m.info);
    std::uint8_t big_endian = 0;
    stream.next(m.info.height);
    stream.next(m.info.width);
    stream.next(m.info.encoding);
    stream.next(big_endian);
    stream.next(m.info.step);
    m.info.big_endian = big_endian != 0;
    skip_data(stream, m.info);
  }
};

template <>
struct Serializer<loopgate::bag::CompressedHeaderOnly> {
  // sensor_msgs/CompressedImage: Header header, string format, uint8[] data.
  template <typename Stream>
  static void read(Stream& stream, loopgate::bag::CompressedHeaderOnly& m) {
    read_header(stream, m.info);
    m.info.compressed = true;
    stream.next(m.info.encoding);
    skip_data(stream, m.info);
  }
};

}  // namespace serialization
}  // namespace ros

namespace loopgate::bag {

namespace {

constexpr const char* kImageType = "sensor_msgs/Image";
constexpr const char* kCompressedType = "sensor_msgs/CompressedImage";
constexpr const char* kImuType = "sensor_msgs/Imu";

std::int64_t stamp_ns(const ros::Time& t) {
  return static_cast<std::int64_t>(t.sec) * 1000000000 + static_cast<std::int64_t>(t.nsec);
}

std::string message_name(const std::string& topic, std::size_t message) {
  return topic + " message " + std::to_string(message);
}

}  // namespace

BagError::BagError(const std::string& file, const std::string& message)
    : std::runtime_error(file + ": " + message), file_(file), message_(message) {}

struct BagReader::Impl {
  rosbag::Bag bag;
  std::string image_topic;
  bool compressed = false;
  std::vector<rosbag::MessageInstance> image_messages;  // positions in the file of the indexed topic
  mutable std::mutex mutex;                             // rosbag::Bag reads through one buffer

  // The type of `topic`: its connections must all be of one of `types` (name, MD5 sum of the definition this
  // build reads). Throws BagError naming the topic and what it found.
  std::string topic_type(const std::string& file, const std::string& topic, const std::string& topics_text,
                         const std::vector<std::pair<std::string, std::string>>& types) const {
    rosbag::View view(bag, rosbag::TopicQuery(topic));
    std::set<std::string> found;
    for (const rosbag::ConnectionInfo* c : view.getConnections()) found.insert(c->datatype);
    if (found.empty()) {
      throw BagError(file, "topic " + topic + " is not in the bag; its topics: " + topics_text);
    }
    std::string wanted;
    for (const auto& t : types) wanted += (wanted.empty() ? "" : " or ") + t.first;
    const auto known =
        std::find_if(types.begin(), types.end(), [&](const auto& t) { return t.first == *found.begin(); });
    if (found.size() > 1 || known == types.end()) {
      std::string have;
      for (const std::string& t : found) have += (have.empty() ? "" : ", ") + t;
      throw BagError(file, "topic " + topic + " holds " + have + ", expected " + wanted);
    }
    for (const rosbag::ConnectionInfo* c : view.getConnections()) {
      if (c->md5sum != known->second) {
        throw BagError(file, "topic " + topic + ": " + c->datatype + " with MD5 sum " + c->md5sum +
                                 ", another definition than the one this build reads (" + known->second +
                                 ")");
      }
    }
    return known->first;
  }
};

BagReader::BagReader(const std::string& file) : file_(file), impl_(std::make_unique<Impl>()) {
  check_bag_structure(file);  // librosbag trusts the offsets of the index: checked first
  try {
    impl_->bag.open(file, rosbag::bagmode::Read);
    rosbag::View all(impl_->bag);
    std::set<std::string> names;
    for (const rosbag::ConnectionInfo* c : all.getConnections()) {
      if (!names.insert(c->topic).second) continue;
      TopicInfo topic;
      topic.name = c->topic;
      topic.datatype = c->datatype;
      topic.messages = rosbag::View(impl_->bag, rosbag::TopicQuery(c->topic)).size();
      topics_.push_back(std::move(topic));
    }
  } catch (const std::exception& e) {
    throw BagError(file, std::string("cannot read it as a ROS1 bag: ") + e.what());
  }
  std::sort(topics_.begin(), topics_.end(),
            [](const TopicInfo& a, const TopicInfo& b) { return a.name < b.name; });
}

BagReader::~BagReader() = default;

std::string BagReader::topics_text() const {
  if (topics_.empty()) return "none (the bag is empty)";
  std::string text;
  for (const TopicInfo& t : topics_) {
    text += (text.empty() ? "" : ", ") + t.name + " (" + t.datatype + ", " + std::to_string(t.messages) +
            (t.messages == 1 ? " message)" : " messages)");
  }
  return text;
}

std::vector<ImageInfo> BagReader::index_images(const std::string& topic) {
  const std::lock_guard<std::mutex> lock(impl_->mutex);
  const std::string type = impl_->topic_type(
      file_, topic, topics_text(),
      {{kImageType, ros::message_traits::MD5Sum<sensor_msgs::Image>::value()},
       {kCompressedType, ros::message_traits::MD5Sum<sensor_msgs::CompressedImage>::value()}});
  impl_->image_topic = topic;
  impl_->compressed = type == kCompressedType;
  impl_->image_messages.clear();
  std::vector<ImageInfo> infos;
  try {
    rosbag::View view(impl_->bag, rosbag::TopicQuery(topic));
    for (const rosbag::MessageInstance& m : view) {
      impl_->image_messages.push_back(m);
      ImageInfo info;
      try {
        if (impl_->compressed) {
          const auto header = m.instantiate<CompressedHeaderOnly>();
          if (header) info = header->info;  // null only for another MD5 sum, refused by topic_type()
        } else {
          const auto header = m.instantiate<ImageHeaderOnly>();
          if (header) info = header->info;
        }
      } catch (const std::exception& e) {
        info = ImageInfo{};
        info.read_error = std::string("cannot read the message: ") + e.what();
      }
      info.compressed = impl_->compressed;
      info.bag_t_ns = stamp_ns(m.getTime());
      infos.push_back(std::move(info));
    }
  } catch (const BagError&) {
    throw;
  } catch (const std::exception& e) {
    throw BagError(file_, "topic " + topic + ": cannot read its messages: " + e.what());
  }
  return infos;
}

RawImage BagReader::read_image(std::size_t message) const {
  RawImage out;
  const std::lock_guard<std::mutex> lock(impl_->mutex);
  if (message >= impl_->image_messages.size()) {
    throw BagError(file_, message_name(impl_->image_topic, message) + ": no such message (the topic has " +
                              std::to_string(impl_->image_messages.size()) + ")");
  }
  const rosbag::MessageInstance& m = impl_->image_messages[message];
  try {
    out.info.compressed = impl_->compressed;
    out.info.bag_t_ns = stamp_ns(m.getTime());
    if (impl_->compressed) {
      const auto image = m.instantiate<sensor_msgs::CompressedImage>();
      if (!image) throw BagError(file_, message_name(impl_->image_topic, message) + ": not readable");
      out.info.header_t_ns = stamp_ns(image->header.stamp);
      out.info.encoding = image->format;
      out.data = std::move(image->data);
    } else {
      const auto image = m.instantiate<sensor_msgs::Image>();
      if (!image) throw BagError(file_, message_name(impl_->image_topic, message) + ": not readable");
      out.info.header_t_ns = stamp_ns(image->header.stamp);
      out.info.width = image->width;
      out.info.height = image->height;
      out.info.step = image->step;
      out.info.encoding = image->encoding;
      out.info.big_endian = image->is_bigendian != 0;
      out.data = std::move(image->data);
    }
  } catch (const BagError&) {
    throw;
  } catch (const std::exception& e) {
    throw BagError(file_,
                   message_name(impl_->image_topic, message) + ": cannot read the message: " + e.what());
  }
  out.info.data_bytes = out.data.size();
  return out;
}

std::vector<ImuRecord> BagReader::read_imu(const std::string& topic) const {
  const std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->topic_type(file_, topic, topics_text(),
                    {{kImuType, ros::message_traits::MD5Sum<sensor_msgs::Imu>::value()}});
  std::vector<ImuRecord> records;
  try {
    rosbag::View view(impl_->bag, rosbag::TopicQuery(topic));
    for (const rosbag::MessageInstance& m : view) {
      ImuRecord record;
      try {
        const auto imu = m.instantiate<sensor_msgs::Imu>();
        if (imu) {  // null only for another MD5 sum, refused by topic_type()
          record.header_t_ns = stamp_ns(imu->header.stamp);
          record.angular_velocity_radps = {imu->angular_velocity.x, imu->angular_velocity.y,
                                           imu->angular_velocity.z};
          record.linear_acceleration_mps2 = {imu->linear_acceleration.x, imu->linear_acceleration.y,
                                             imu->linear_acceleration.z};
        }
      } catch (const std::exception& e) {
        record.read_error = std::string("cannot read the message: ") + e.what();
      }
      records.push_back(std::move(record));
    }
  } catch (const std::exception& e) {
    throw BagError(file_, "topic " + topic + ": cannot read its messages: " + e.what());
  }
  return records;
}

}  // namespace loopgate::bag
