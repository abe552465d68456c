#include "io/png_grey.hpp"

#include <libdeflate.h>

#include <array>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

namespace loopgate {

namespace {

constexpr std::array<unsigned char, 8> kSignature = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
// Larger images go the general way (no fast-path allocation is ever larger than this).
constexpr std::uint64_t kMaxPixels = std::uint64_t{1} << 28;

std::uint32_t read_be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

bool is_type(const unsigned char* p, const char* name) {
  return std::memcmp(p, name, 4) == 0;
}

// Ancillary chunks that cannot change the pixels OpenCV's decoder returns for an 8-bit grey image: text,
// time and physical pixel size. Any other chunk (tRNS, sBIT, gAMA, iCCP, ...) sends the file the general way.
bool harmless_ancillary(const unsigned char* type) {
  return is_type(type, "tEXt") || is_type(type, "zTXt") || is_type(type, "iTXt") || is_type(type, "tIME") ||
         is_type(type, "pHYs");
}

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};

// Per thread: the decompressor (about 10 KB of tables) and the buffers, reused from frame to frame (a
// 752 x 480 image inflates to 361 KB, which malloc would otherwise map and unmap for every frame).
struct Scratch {
  std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> decompressor{libdeflate_alloc_decompressor()};
  std::vector<unsigned char> idat;      // the IDAT chunks joined, when there are several
  std::vector<unsigned char> filtered;  // the inflated rows, each led by its filter type byte
};

Scratch& scratch() {
  thread_local Scratch s;
  return s;
}

unsigned char paeth(unsigned char a, unsigned char b, unsigned char c) {
  const int p = int{a} + int{b} - int{c};
  const int pa = std::abs(p - int{a});
  const int pb = std::abs(p - int{b});
  const int pc = std::abs(p - int{c});
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

// Rows of `filtered` (filter byte + width bytes each) into `image`; false on an unknown filter type.
bool unfilter(const unsigned char* filtered, cv::Mat& image) {
  const auto width = static_cast<std::size_t>(image.cols);
  const std::vector<unsigned char> zeros(width, 0);  // the row above the first row
  const unsigned char* prior = zeros.data();
  for (int y = 0; y < image.rows; ++y) {
    const unsigned char* in = filtered + static_cast<std::size_t>(y) * (width + 1);
    const unsigned char type = in[0];
    ++in;
    unsigned char* out = image.ptr<unsigned char>(y);
    switch (type) {
      case 0: std::memcpy(out, in, width); break;
      case 1:  // Sub
        out[0] = in[0];
        for (std::size_t x = 1; x < width; ++x) out[x] = static_cast<unsigned char>(in[x] + out[x - 1]);
        break;
      case 2:  // Up
        for (std::size_t x = 0; x < width; ++x) out[x] = static_cast<unsigned char>(in[x] + prior[x]);
        break;
      case 3:  // Average
        out[0] = static_cast<unsigned char>(in[0] + (prior[0] >> 1));
        for (std::size_t x = 1; x < width; ++x)
          out[x] = static_cast<unsigned char>(in[x] + ((unsigned{out[x - 1]} + unsigned{prior[x]}) >> 1));
        break;
      case 4:                                                   // Paeth
        out[0] = static_cast<unsigned char>(in[0] + prior[0]);  // paeth(0, b, 0) = b
        for (std::size_t x = 1; x < width; ++x)
          out[x] = static_cast<unsigned char>(in[x] + paeth(out[x - 1], prior[x], prior[x - 1]));
        break;
      default: return false;
    }
    prior = out;
  }
  return true;
}

}  // namespace

cv::Mat decode_png_grey8(const unsigned char* bytes, std::size_t size) {
  if (bytes == nullptr || size < kSignature.size() ||
      std::memcmp(bytes, kSignature.data(), kSignature.size()) != 0)
    return {};
  Scratch& s = scratch();
  if (!s.decompressor) return {};
  std::size_t pos = kSignature.size();
  std::uint32_t width = 0, height = 0;
  bool header = false, end = false;
  const unsigned char* single_idat = nullptr;  // the only IDAT chunk's data, when there is one
  std::size_t idat_size = 0;
  int idat_chunks = 0;
  bool idat_done = false;  // a chunk followed the IDAT run (IDATs must be consecutive)
  s.idat.clear();
  while (!end) {
    if (size - pos < 12) return {};  // truncated: no room for length, type and CRC
    const std::uint32_t length = read_be32(bytes + pos);
    const unsigned char* type = bytes + pos + 4;
    if (length > 0x7fffffffU || size - pos - 12 < length) return {};
    const unsigned char* data = type + 4;
    if (read_be32(data + length) != libdeflate_crc32(0, type, std::size_t{length} + 4)) return {};
    if (!header) {
      if (!is_type(type, "IHDR") || length != 13) return {};
      width = read_be32(data);
      height = read_be32(data + 4);
      // bit depth 8, colour type 0 (grey), compression 0, filter method 0, no interlace
      if (data[8] != 8 || data[9] != 0 || data[10] != 0 || data[11] != 0 || data[12] != 0) return {};
      if (width == 0 || height == 0 || width > 0x7fffffffU || height > 0x7fffffffU ||
          std::uint64_t{width} * height > kMaxPixels)
        return {};
      header = true;
    } else if (is_type(type, "IDAT")) {
      if (idat_done) return {};
      ++idat_chunks;
      if (idat_chunks == 1) {
        single_idat = data;
      } else {
        if (idat_chunks == 2) s.idat.assign(single_idat, single_idat + idat_size);
        s.idat.insert(s.idat.end(), data, data + length);
      }
      idat_size += length;
    } else if (is_type(type, "IEND")) {
      end = true;
    } else if (harmless_ancillary(type)) {
      if (idat_chunks > 0) idat_done = true;
    } else {
      return {};  // IHDR twice, PLTE, tRNS, sBIT, gAMA, an unknown chunk: the general way
    }
    pos += std::size_t{length} + 12;
  }
  if (idat_chunks == 0) return {};
  const unsigned char* stream = idat_chunks == 1 ? single_idat : s.idat.data();
  const std::size_t filtered_size = std::size_t{height} * (std::size_t{width} + 1);
  s.filtered.resize(filtered_size);
  // Exactly filtered_size bytes, and the stream's Adler-32 must match (libdeflate checks it).
  if (libdeflate_zlib_decompress(s.decompressor.get(), stream, idat_size, s.filtered.data(), filtered_size,
                                 nullptr) != LIBDEFLATE_SUCCESS)
    return {};
  cv::Mat image(static_cast<int>(height), static_cast<int>(width), CV_8UC1);
  if (!unfilter(s.filtered.data(), image)) return {};
  return image;
}

}  // namespace loopgate
