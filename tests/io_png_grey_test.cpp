// The 8-bit grey PNG fast path (io/png_grey.hpp): the pixels of cv::imdecode for every filter type, row width
// and IDAT split; an empty answer (the general way: OpenCV, as before) for every file it is not sure of.
// Damaged files through LoadedDataset::decode keep their error naming the file (io_dataset_test,
// e2e_hostile_test).
#include <gtest/gtest.h>
#include <libdeflate.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "io/png_grey.hpp"

namespace loopgate {
namespace {

using Bytes = std::vector<unsigned char>;

void put_be32(Bytes& out, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<unsigned char>(v >> shift));
}

void put_chunk(Bytes& out, const char* type, const Bytes& data) {
  put_be32(out, static_cast<std::uint32_t>(data.size()));
  Bytes body(type, type + 4);
  body.insert(body.end(), data.begin(), data.end());
  out.insert(out.end(), body.begin(), body.end());
  put_be32(out, libdeflate_crc32(0, body.data(), body.size()));
}

unsigned char paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return static_cast<unsigned char>(pa <= pb && pa <= pc ? a : (pb <= pc ? b : c));
}

struct PngSpec {
  int colour_type = 0;
  int bit_depth = 8;
  int interlace = 0;
  std::vector<int> filters;  // per row, cycled; empty: 0..4 cycled
  int idat_chunks = 1;
  std::vector<std::pair<std::string, Bytes>> extra_chunks;  // between IHDR and IDAT
};

// A PNG of `image` written by hand: each row filtered with the given filter type, zlib-compressed by
// libdeflate, split into `idat_chunks` IDAT chunks.
Bytes encode(const cv::Mat& image, const PngSpec& spec = {}) {
  Bytes out = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  Bytes ihdr;
  put_be32(ihdr, static_cast<std::uint32_t>(image.cols));
  put_be32(ihdr, static_cast<std::uint32_t>(image.rows));
  ihdr.insert(ihdr.end(),
              {static_cast<unsigned char>(spec.bit_depth), static_cast<unsigned char>(spec.colour_type), 0, 0,
               static_cast<unsigned char>(spec.interlace)});
  put_chunk(out, "IHDR", ihdr);
  for (const auto& [type, data] : spec.extra_chunks) put_chunk(out, type.c_str(), data);
  Bytes raw;
  const std::vector<int> filters = spec.filters.empty() ? std::vector<int>{0, 1, 2, 3, 4} : spec.filters;
  for (int y = 0; y < image.rows; ++y) {
    const int type = filters[static_cast<std::size_t>(y) % filters.size()];
    raw.push_back(static_cast<unsigned char>(type));
    const unsigned char* row = image.ptr<unsigned char>(y);
    const unsigned char* up = y > 0 ? image.ptr<unsigned char>(y - 1) : nullptr;
    for (int x = 0; x < image.cols; ++x) {
      const int a = x > 0 ? row[x - 1] : 0, b = up ? up[x] : 0, c = (up && x > 0) ? up[x - 1] : 0;
      int predictor = 0;
      if (type == 1) predictor = a;
      if (type == 2) predictor = b;
      if (type == 3) predictor = (a + b) / 2;
      if (type == 4) predictor = paeth(a, b, c);
      raw.push_back(static_cast<unsigned char>(row[x] - predictor));
    }
  }
  libdeflate_compressor* compressor = libdeflate_alloc_compressor(6);
  Bytes z(libdeflate_zlib_compress_bound(compressor, raw.size()));
  z.resize(libdeflate_zlib_compress(compressor, raw.data(), raw.size(), z.data(), z.size()));
  libdeflate_free_compressor(compressor);
  const std::size_t step = (z.size() + static_cast<std::size_t>(spec.idat_chunks) - 1) / spec.idat_chunks;
  for (std::size_t begin = 0; begin < z.size(); begin += step)
    put_chunk(out, "IDAT",
              Bytes(z.begin() + static_cast<std::ptrdiff_t>(begin),
                    z.begin() + static_cast<std::ptrdiff_t>(std::min(z.size(), begin + step))));
  put_chunk(out, "IEND", {});
  return out;
}

cv::Mat random_grey(int rows, int cols, unsigned seed) {
  cv::Mat image(rows, cols, CV_8UC1);
  std::mt19937 rng(seed);
  // Smooth ramps plus noise, so that every predictor sees both small and wrapping residuals.
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x)
      image.at<unsigned char>(y, x) = static_cast<unsigned char>((3 * x + 5 * y) % 256 + rng() % 64);
  return image;
}

cv::Mat fast(const Bytes& png) {
  return decode_png_grey8(png.data(), png.size());
}

cv::Mat opencv(const Bytes& png) {
  return cv::imdecode(png, cv::IMREAD_UNCHANGED);
}

void expect_same(const cv::Mat& a, const cv::Mat& b) {
  ASSERT_FALSE(a.empty());
  ASSERT_EQ(a.type(), CV_8UC1);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(b.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
}

TEST(IoPngGrey, EveryFilterTypeGivesOpenCvsPixels) {
  for (int filter = 0; filter <= 4; ++filter) {
    SCOPED_TRACE("filter " + std::to_string(filter));
    const cv::Mat image = random_grey(37, 53, static_cast<unsigned>(filter));
    PngSpec spec;
    spec.filters = {filter};
    const Bytes png = encode(image, spec);
    expect_same(fast(png), image);
    expect_same(fast(png), opencv(png));
  }
}

// Every ordered pair of filter types in consecutive rows (each row is unfiltered from the one above), then
// an odd last row.
TEST(IoPngGrey, EveryPairOfFilterTypesInConsecutiveRows) {
  PngSpec spec;
  for (int first = 0; first <= 4; ++first)
    for (int second = 0; second <= 4; ++second) spec.filters.insert(spec.filters.end(), {first, second});
  spec.filters.push_back(4);
  for (const int cols : {1, 2, 61}) {
    SCOPED_TRACE("width " + std::to_string(cols));
    const cv::Mat image =
        random_grey(static_cast<int>(spec.filters.size()), cols, static_cast<unsigned>(cols));
    const Bytes png = encode(image, spec);
    expect_same(fast(png), image);
  }
}

TEST(IoPngGrey, MixedFiltersOddSizesAndSplitStreams) {
  for (const auto& [rows, cols] :
       std::vector<std::pair<int, int>>{{1, 1}, {1, 9}, {9, 1}, {480, 752}, {31, 17}}) {
    for (const int chunks : {1, 2, 7}) {
      SCOPED_TRACE(std::to_string(rows) + "x" + std::to_string(cols) + " in " + std::to_string(chunks));
      const cv::Mat image = random_grey(rows, cols, static_cast<unsigned>(rows * 31 + cols));
      PngSpec spec;
      spec.idat_chunks = chunks;
      const Bytes png = encode(image, spec);
      expect_same(fast(png), opencv(png));
    }
  }
}

// Rows are unfiltered sixteen or eight at a time (diagonal wavefronts in SIMD lanes) where SSE2 is there, the
// rest two at a time: random filter types per row over heights around multiples of 8 and 16 and widths
// around multiples of 8, so that every lane meets every filter type next to every other, at both image
// edges, across the two bands of sixteen rows and in the rows left over at the bottom.
TEST(IoPngGrey, RandomFilterTypesPerRowInEveryBandShape) {
  std::mt19937 rng(7);
  for (int rows = 7; rows <= 41; ++rows) {
    for (const int cols : {1, 2, 7, 8, 9, 15, 16, 17, 33, 64}) {
      SCOPED_TRACE(std::to_string(rows) + "x" + std::to_string(cols));
      const cv::Mat image = random_grey(rows, cols, static_cast<unsigned>(rows * 101 + cols));
      PngSpec spec;
      for (int y = 0; y < rows; ++y) spec.filters.push_back(static_cast<int>(rng() % 5));
      const Bytes png = encode(image, spec);
      expect_same(fast(png), opencv(png));
      EXPECT_EQ(cv::norm(fast(png), image, cv::NORM_INF), 0.0);
    }
  }
}

TEST(IoPngGrey, OpenCvsOwnFilesDecodeTheSame) {
  const cv::Mat image = random_grey(120, 200, 7);
  for (const int level : {0, 1, 9}) {
    Bytes png;
    ASSERT_TRUE(cv::imencode(".png", image, png, {cv::IMWRITE_PNG_COMPRESSION, level}));
    expect_same(fast(png), image);
  }
}

TEST(IoPngGrey, HarmlessChunksAreSkipped) {
  const cv::Mat image = random_grey(20, 30, 3);
  PngSpec spec;
  spec.extra_chunks = {{"tEXt", {'a', 0, 'b'}}, {"pHYs", Bytes(9, 1)}};
  expect_same(fast(encode(image, spec)), image);
}

// Each of these must go the general way (an empty answer), never a wrong image.
TEST(IoPngGrey, AnythingUnexpectedGoesTheGeneralWay) {
  const cv::Mat image = random_grey(20, 30, 5);
  const Bytes good = encode(image);
  ASSERT_FALSE(fast(good).empty());

  auto with_spec = [&](auto change) {
    PngSpec spec;
    change(spec);
    return fast(encode(image, spec));
  };
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.interlace = 1; }).empty()) << "interlaced";
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.bit_depth = 16; }).empty()) << "16-bit";
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.colour_type = 2; }).empty()) << "colour";
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.extra_chunks = {{"tRNS", {0, 0}}}; }).empty()) << "tRNS";
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.extra_chunks = {{"gAMA", Bytes(4, 0)}}; }).empty()) << "gAMA";
  EXPECT_TRUE(with_spec([](PngSpec& s) { s.filters = {5}; }).empty()) << "filter type 5";

  Bytes crc = good;
  crc[good.size() - 20] ^= 0x01;  // a byte inside the last IDAT's data
  EXPECT_TRUE(fast(crc).empty()) << "IDAT damaged";
  PngSpec text;
  text.extra_chunks = {{"tEXt", {'k', 0, 'v'}}};
  Bytes text_crc = encode(image, text);
  ASSERT_FALSE(fast(text_crc).empty());
  text_crc[33 + 8] ^= 0x01;  // the tEXt chunk's first data byte: only its CRC tells
  EXPECT_TRUE(fast(text_crc).empty()) << "CRC mismatch";
  for (const std::size_t keep :
       {std::size_t{0}, std::size_t{7}, std::size_t{20}, good.size() / 2, good.size() - 1})
    EXPECT_TRUE(fast(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(keep))).empty())
        << "truncated to " << keep;
  Bytes not_png = good;
  not_png[1] = 'Q';
  EXPECT_TRUE(fast(not_png).empty()) << "signature";
  EXPECT_TRUE(decode_png_grey8(nullptr, 0).empty());

  // A zlib stream that inflates to fewer bytes than the image needs (IHDR says one row more).
  Bytes tall = encode(image);
  tall[8 + 8 + 7] = static_cast<unsigned char>(image.rows + 1);  // IHDR height's low byte
  const std::uint32_t crc_ihdr = libdeflate_crc32(0, tall.data() + 12, 17);
  for (int k = 0; k < 4; ++k) tall[29 + k] = static_cast<unsigned char>(crc_ihdr >> (24 - 8 * k));
  EXPECT_TRUE(fast(tall).empty()) << "short stream";

  // IDAT chunks that are not consecutive.
  PngSpec split;
  split.idat_chunks = 2;
  Bytes apart = encode(image, split);
  // Move a tEXt chunk between the two IDATs: rebuild by hand.
  {
    Bytes rebuilt(apart.begin(), apart.begin() + 33);  // signature + IHDR
    std::size_t pos = 33;
    int idat = 0;
    while (pos < apart.size()) {
      const std::uint32_t length = (std::uint32_t{apart[pos]} << 24) | (std::uint32_t{apart[pos + 1]} << 16) |
                                   (std::uint32_t{apart[pos + 2]} << 8) | std::uint32_t{apart[pos + 3]};
      rebuilt.insert(rebuilt.end(), apart.begin() + static_cast<std::ptrdiff_t>(pos),
                     apart.begin() + static_cast<std::ptrdiff_t>(pos + 12 + length));
      if (std::string(apart.begin() + static_cast<std::ptrdiff_t>(pos + 4),
                      apart.begin() + static_cast<std::ptrdiff_t>(pos + 8)) == "IDAT" &&
          ++idat == 1)
        put_chunk(rebuilt, "tEXt", {'k', 0, 'v'});
      pos += 12 + length;
    }
    EXPECT_TRUE(fast(rebuilt).empty()) << "IDAT chunks apart";
  }
}

// Damaged files at random (bytes flipped, lengths changed, cut short): never a crash or a read out of bounds
// (the asan preset runs this), and an image only when OpenCV decodes the same bytes to the same pixels.
TEST(IoPngGrey, RandomlyDamagedFilesNeverGiveAWrongImage) {
  const cv::Mat image = random_grey(24, 40, 9);
  PngSpec spec;
  spec.idat_chunks = 3;
  spec.extra_chunks = {{"tEXt", {'k', 0, 'v'}}};
  const Bytes good = encode(image, spec);
  std::mt19937 rng(2026);
  int decoded = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    Bytes bad = good;
    const int flips = 1 + static_cast<int>(rng() % 4);
    for (int f = 0; f < flips; ++f) bad[rng() % bad.size()] = static_cast<unsigned char>(rng());
    if (trial % 3 == 0) bad.resize(rng() % bad.size());
    const cv::Mat fast_image = fast(bad);
    if (fast_image.empty()) continue;
    ++decoded;
    expect_same(fast_image, opencv(bad));
  }
  std::printf("%d of 3000 damaged files decoded by the fast path (each equal to OpenCV's)\n", decoded);
}

}  // namespace
}  // namespace loopgate
