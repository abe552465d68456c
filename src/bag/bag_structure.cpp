// C++17, like the rest of src/bag. The byte layout is that of the ROS1 bag format 2.0: after the line
// "#ROSBAG V2.0\n", records of [uint32 header length][header][uint32 data length][data], a header being
// fields of [uint32 field length]["name=value"], little-endian throughout.
#include "bag/bag_structure.hpp"

#include <bzlib.h>
#include <roslz4/lz4s.h>

#include <cstdint>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <vector>

#include "bag/bag_reader.hpp"

namespace loopgate::bag {
namespace {

constexpr std::uint8_t kOpMessageDefinition = 0x01;
constexpr std::uint8_t kOpMessageData = 0x02;
constexpr std::uint8_t kOpBagHeader = 0x03;
constexpr std::uint8_t kOpIndexData = 0x04;
constexpr std::uint8_t kOpChunk = 0x05;
constexpr std::uint8_t kOpChunkInfo = 0x06;
constexpr std::uint8_t kOpConnection = 0x07;
// A chunk that says it decompresses to more than this is refused (librosbag would allocate it whole).
constexpr std::uint64_t kMaxChunkBytes = std::uint64_t{1} << 30;

using Fields = std::map<std::string, std::string>;

std::uint32_t u32(const char* p) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return v;
}

std::uint64_t u64(const char* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return v;
}

// Bytes of the file or of a decompressed chunk, read at an offset with a bounds check.
class Bytes {
 public:
  virtual ~Bytes() = default;
  virtual std::uint64_t size() const = 0;
  // The n bytes at pos; false when they are not all inside.
  virtual bool read(std::uint64_t pos, std::uint64_t n, std::string& out) = 0;
};

class FileBytes : public Bytes {
 public:
  FileBytes(std::ifstream& in, std::uint64_t begin, std::uint64_t size)
      : in_(in), begin_(begin), size_(size) {}
  std::uint64_t size() const override { return size_; }
  bool read(std::uint64_t pos, std::uint64_t n, std::string& out) override {
    if (pos > size_ || n > size_ - pos) return false;
    out.resize(n);
    in_.clear();
    in_.seekg(static_cast<std::streamoff>(begin_ + pos));
    in_.read(out.data(), static_cast<std::streamsize>(n));
    return static_cast<std::uint64_t>(in_.gcount()) == n;
  }

 private:
  std::ifstream& in_;
  std::uint64_t begin_;
  std::uint64_t size_;
};

class BufferBytes : public Bytes {
 public:
  explicit BufferBytes(std::vector<char> data) : data_(std::move(data)) {}
  std::uint64_t size() const override { return data_.size(); }
  bool read(std::uint64_t pos, std::uint64_t n, std::string& out) override {
    if (pos > data_.size() || n > data_.size() - pos) return false;
    out.assign(data_.data() + pos, n);
    return true;
  }

 private:
  std::vector<char> data_;
};

struct Record {
  std::uint64_t pos = 0;
  std::uint32_t header_bytes = 0;
  Fields fields;
  std::uint32_t data_bytes = 0;
  std::uint64_t data_pos = 0;
  std::uint64_t end = 0;  // the byte after the data
};

class Checker {
 public:
  explicit Checker(const std::string& file) : file_(file) {}

  [[noreturn]] void fail(const std::string& what) const {
    throw BagError(file_, "cannot read it as a ROS1 bag: " + what);
  }

  // "name=value" fields filling exactly `bytes` (what ros::Header::parse reads without a bounds check).
  Fields parse_fields(const std::string& bytes, const std::string& where) const {
    Fields fields;
    std::size_t i = 0;
    while (i < bytes.size()) {
      if (bytes.size() - i < 4) fail(where + ": a field length is cut off by the end of the header");
      const std::uint32_t n = u32(bytes.data() + i);
      i += 4;
      if (n > bytes.size() - i) {
        fail(where + ": a field of " + std::to_string(n) + " bytes runs past the end of the header (" +
             std::to_string(bytes.size() - i) + " bytes left)");
      }
      const std::string field = bytes.substr(i, n);
      i += n;
      const std::size_t eq = field.find('=');
      if (eq == std::string::npos) fail(where + ": a header field without '='");
      fields[field.substr(0, eq)] = field.substr(eq + 1);
    }
    return fields;
  }

  // The record at pos of `bytes`; with_data: its data must be inside too.
  Record record(Bytes& bytes, std::uint64_t pos, const std::string& where, bool with_data = true) const {
    Record r;
    r.pos = pos;
    std::string buf;
    if (!bytes.read(pos, 4, buf)) fail(where + " at byte " + std::to_string(pos) + ": past the end");
    r.header_bytes = u32(buf.data());
    if (!bytes.read(pos + 4, r.header_bytes, buf)) {
      fail(where + " at byte " + std::to_string(pos) + ": a header of " + std::to_string(r.header_bytes) +
           " bytes runs past the end (" + std::to_string(bytes.size()) + " bytes)");
    }
    r.fields = parse_fields(buf, where + " at byte " + std::to_string(pos));
    const std::uint64_t length_pos = pos + 4 + r.header_bytes;
    if (!bytes.read(length_pos, 4, buf)) fail(where + " at byte " + std::to_string(pos) + ": no data length");
    r.data_bytes = u32(buf.data());
    r.data_pos = length_pos + 4;
    r.end = r.data_pos + r.data_bytes;
    if (with_data && r.end > bytes.size()) {
      fail(where + " at byte " + std::to_string(pos) + ": data of " + std::to_string(r.data_bytes) +
           " bytes runs past the end (" + std::to_string(bytes.size()) + " bytes)");
    }
    return r;
  }

  std::uint8_t op(const Record& r, const std::string& where) const {
    const auto it = r.fields.find("op");
    if (it == r.fields.end() || it->second.size() != 1) {
      fail(where + " at byte " + std::to_string(r.pos) + ": no one-byte 'op' field");
    }
    return static_cast<std::uint8_t>(it->second[0]);
  }

  void expect_op(const Record& r, std::uint8_t wanted, const std::string& where) const {
    const std::uint8_t got = op(r, where);
    if (got != wanted) {
      fail(where + " at byte " + std::to_string(r.pos) + ": record op " + std::to_string(got) +
           ", expected " + std::to_string(wanted));
    }
  }

  const std::string& field(const Record& r, const std::string& name, std::size_t bytes,
                           const std::string& where) const {
    const auto it = r.fields.find(name);
    if (it == r.fields.end() || (bytes != 0 && it->second.size() != bytes)) {
      fail(where + " at byte " + std::to_string(r.pos) + ": no field '" + name + "'" +
           (bytes != 0 ? " of " + std::to_string(bytes) + " bytes" : ""));
    }
    return it->second;
  }

  // The message an index entry points to: librosbag reads record headers from `offset` on while they are
  // message definitions or connections (skipping 4 + header + 4 bytes each), then the message data.
  void message(Bytes& chunk, std::uint64_t offset, const std::string& where) const {
    for (;;) {
      const Record r = record(chunk, offset, where, false);
      const std::uint8_t o = op(r, where);
      if (o == kOpMessageDefinition || o == kOpConnection) {
        offset = r.data_pos;
        continue;
      }
      if (o != kOpMessageData) return;  // librosbag refuses it with an exception of its own
      if (r.end > chunk.size()) {
        fail(where + ": message data of " + std::to_string(r.data_bytes) + " bytes runs past the chunk (" +
             std::to_string(chunk.size()) + " bytes)");
      }
      return;
    }
  }

  std::vector<char> decompress(const std::string& compression, const std::string& data, std::uint32_t size,
                               const std::string& where) const {
    std::vector<char> out(size);
    std::string in = data;
    unsigned int produced = size;
    bool ok = false;
    if (compression == "bz2") {
      ok = BZ2_bzBuffToBuffDecompress(out.data(), &produced, in.data(), static_cast<unsigned int>(in.size()),
                                      0, 0) == BZ_OK;
    } else if (compression == "lz4") {
      ok = roslz4_buffToBuffDecompress(in.data(), static_cast<unsigned int>(in.size()), out.data(),
                                       &produced) == 0;
    } else {
      fail(where + ": compression '" + compression + "', expected none, bz2 or lz4");
    }
    if (!ok) fail(where + ": its " + compression + " data does not decompress");
    if (produced != size) {
      fail(where + ": decompresses to " + std::to_string(produced) + " bytes, its header says " +
           std::to_string(size));
    }
    return out;
  }

  void run() {
    std::ifstream in(file_, std::ios::binary);
    if (!in) return;  // librosbag says it cannot open the file
    in.seekg(0, std::ios::end);
    const auto end = static_cast<std::uint64_t>(in.tellg());
    FileBytes file(in, 0, end);
    std::string magic;
    const std::string v2 = "#ROSBAG V2.0\n";
    if (!file.read(0, v2.size(), magic) || magic.rfind("#ROSBAG V", 0) != 0) return;  // not a bag: librosbag
    if (magic != v2) fail("format " + magic.substr(8, 4) + "; this build reads the bag format 2.0");

    const Record header = record(file, v2.size(), "the bag header record");
    expect_op(header, kOpBagHeader, "the bag header record");
    if (header.fields.count("encryptor") && !header.fields.at("encryptor").empty()) {
      fail("it is encrypted (" + header.fields.at("encryptor") + "); encrypted bags are not read");
    }
    const std::uint64_t index_pos = u64(field(header, "index_pos", 8, "the bag header record").data());
    const std::uint32_t connection_count =
        u32(field(header, "conn_count", 4, "the bag header record").data());
    const std::uint32_t chunk_count = u32(field(header, "chunk_count", 4, "the bag header record").data());
    if (index_pos == 0) return;  // unindexed: librosbag says so
    if (index_pos >= end) {
      fail("the bag header puts the index at byte " + std::to_string(index_pos) +
           ", past the end of the file (" + std::to_string(end) +
           " bytes); the bag is truncated or was not closed (rosbag reindex)");
    }

    std::set<std::uint32_t> connections;
    std::uint64_t pos = index_pos;
    for (std::uint32_t c = 0; c < connection_count; ++c) {
      const Record r = record(file, pos, "connection record " + std::to_string(c));
      expect_op(r, kOpConnection, "connection record " + std::to_string(c));
      connections.insert(u32(field(r, "conn", 4, "connection record " + std::to_string(c)).data()));
      field(r, "topic", 0, "connection record " + std::to_string(c));
      std::string data;
      file.read(r.data_pos, r.data_bytes, data);
      parse_fields(data, "connection record " + std::to_string(c) + " at byte " + std::to_string(r.pos));
      pos = r.end;
    }
    struct ChunkInfo {
      std::uint64_t pos = 0;
      std::uint32_t connections = 0;
    };
    std::vector<ChunkInfo> chunks;
    for (std::uint32_t c = 0; c < chunk_count; ++c) {
      const std::string where = "chunk info record " + std::to_string(c);
      const Record r = record(file, pos, where);
      expect_op(r, kOpChunkInfo, where);
      if (u32(field(r, "ver", 4, where).data()) != 1) fail(where + ": version other than 1");
      ChunkInfo info;
      info.pos = u64(field(r, "chunk_pos", 8, where).data());
      field(r, "start_time", 8, where);
      field(r, "end_time", 8, where);
      info.connections = u32(field(r, "count", 4, where).data());
      if (static_cast<std::uint64_t>(info.connections) * 8 != r.data_bytes) {
        fail(where + " at byte " + std::to_string(r.pos) + ": " + std::to_string(info.connections) +
             " connections need " + std::to_string(std::uint64_t{info.connections} * 8) +
             " bytes of data, it has " + std::to_string(r.data_bytes));
      }
      chunks.push_back(info);
      pos = r.end;
    }

    for (std::size_t c = 0; c < chunks.size(); ++c) {
      const std::string where = "chunk " + std::to_string(c) + " at byte " + std::to_string(chunks[c].pos);
      if (chunks[c].pos >= end)
        fail(where + ": past the end of the file (" + std::to_string(end) + " bytes)");
      const Record chunk = record(file, chunks[c].pos, "chunk " + std::to_string(c));
      expect_op(chunk, kOpChunk, "chunk " + std::to_string(c));
      const std::string compression = field(chunk, "compression", 0, where);
      const std::uint32_t size = u32(field(chunk, "size", 4, where).data());
      std::unique_ptr<Bytes> content;
      if (compression == "none") {
        if (size != chunk.data_bytes) {
          fail(where + ": uncompressed, with " + std::to_string(chunk.data_bytes) +
               " bytes of data but size " + std::to_string(size));
        }
        content = std::make_unique<FileBytes>(in, chunk.data_pos, chunk.data_bytes);
      } else {
        if (size > kMaxChunkBytes) {
          fail(where + ": says it decompresses to " + std::to_string(size) + " bytes, more than " +
               std::to_string(kMaxChunkBytes));
        }
        std::string data;
        file.read(chunk.data_pos, chunk.data_bytes, data);
        content = std::make_unique<BufferBytes>(decompress(compression, data, size, where));
      }
      std::uint64_t index = chunk.end;
      for (std::uint32_t k = 0; k < chunks[c].connections; ++k) {
        const std::string index_where = "index record " + std::to_string(k) + " of " + where;
        const Record r = record(file, index, index_where);
        expect_op(r, kOpIndexData, index_where);
        if (u32(field(r, "ver", 4, index_where).data()) != 1) fail(index_where + ": version other than 1");
        const std::uint32_t connection = u32(field(r, "conn", 4, index_where).data());
        if (!connections.count(connection)) {
          fail(index_where + ": connection " + std::to_string(connection) + " is not in the bag's index");
        }
        const std::uint32_t count = u32(field(r, "count", 4, index_where).data());
        if (static_cast<std::uint64_t>(count) * 12 != r.data_bytes) {
          fail(index_where + ": " + std::to_string(count) + " entries need " +
               std::to_string(std::uint64_t{count} * 12) + " bytes of data, it has " +
               std::to_string(r.data_bytes));
        }
        std::string entries;
        file.read(r.data_pos, r.data_bytes, entries);
        for (std::uint32_t e = 0; e < count; ++e) {
          const std::uint32_t offset = u32(entries.data() + 12 * e + 8);
          const std::string entry_where = index_where + ", entry " + std::to_string(e) + " (offset " +
                                          std::to_string(offset) + " in the chunk of " +
                                          std::to_string(content->size()) + " bytes)";
          message(*content, offset, entry_where);
        }
        index = r.end;
      }
    }
  }

 private:
  std::string file_;
};

}  // namespace

void check_bag_structure(const std::string& file) {
  Checker(file).run();
}

}  // namespace loopgate::bag
