// DIRD extraction against the test vectors of ../shared/docs/dird.md §1 (byte sums, MD5, hand-checked
// bytes), plus the colour conversion, the resize rule and the vertical flip.
#include "stages/dird/dird_extractor.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "test_support.hpp"

namespace loopgate {
namespace {

// Self-contained MD5 (RFC 1321), enough for checking 3456-byte test vectors.
std::string md5_hex(const std::uint8_t* data, std::size_t size) {
  static const std::uint32_t kS[64] = {7, 12, 17, 22, 7, 12, 17, 22, 7, 12, 17, 22, 7, 12, 17, 22,
                                       5, 9,  14, 20, 5, 9,  14, 20, 5, 9,  14, 20, 5, 9,  14, 20,
                                       4, 11, 16, 23, 4, 11, 16, 23, 4, 11, 16, 23, 4, 11, 16, 23,
                                       6, 10, 15, 21, 6, 10, 15, 21, 6, 10, 15, 21, 6, 10, 15, 21};
  std::uint32_t k_table[64];
  for (int i = 0; i < 64; ++i) {
    k_table[i] = static_cast<std::uint32_t>(
        std::floor(std::fabs(std::sin(static_cast<double>(i + 1))) * 4294967296.0));
  }
  std::vector<std::uint8_t> msg(data, data + size);
  const std::uint64_t bit_len = static_cast<std::uint64_t>(size) * 8u;
  msg.push_back(0x80);
  while (msg.size() % 64 != 56) msg.push_back(0);
  for (int i = 0; i < 8; ++i) msg.push_back(static_cast<std::uint8_t>(bit_len >> (8 * i)));
  std::uint32_t a0 = 0x67452301, b0 = 0xefcdab89, c0 = 0x98badcfe, d0 = 0x10325476;
  for (std::size_t off = 0; off < msg.size(); off += 64) {
    std::uint32_t m[16];
    for (int i = 0; i < 16; ++i) {
      m[i] = static_cast<std::uint32_t>(msg[off + 4 * i]) |
             (static_cast<std::uint32_t>(msg[off + 4 * i + 1]) << 8) |
             (static_cast<std::uint32_t>(msg[off + 4 * i + 2]) << 16) |
             (static_cast<std::uint32_t>(msg[off + 4 * i + 3]) << 24);
    }
    std::uint32_t a = a0, b = b0, c = c0, d = d0;
    for (std::uint32_t i = 0; i < 64; ++i) {
      std::uint32_t f = 0;
      std::uint32_t g = 0;
      if (i < 16) {
        f = (b & c) | (~b & d);
        g = i;
      } else if (i < 32) {
        f = (d & b) | (~d & c);
        g = (5 * i + 1) % 16;
      } else if (i < 48) {
        f = b ^ c ^ d;
        g = (3 * i + 5) % 16;
      } else {
        f = c ^ (b | ~d);
        g = (7 * i) % 16;
      }
      f = f + a + k_table[i] + m[g];
      a = d;
      d = c;
      c = b;
      b = b + ((f << kS[i]) | (f >> (32 - kS[i])));
    }
    a0 += a;
    b0 += b;
    c0 += c;
    d0 += d;
  }
  std::string hex;
  for (std::uint32_t word : {a0, b0, c0, d0}) {
    for (int i = 0; i < 4; ++i) {
      char buf[3];
      std::snprintf(buf, sizeof buf, "%02x", (word >> (8 * i)) & 0xffu);
      hex += buf;
    }
  }
  return hex;
}

std::string md5_hex(const Descriptor& d) {
  return md5_hex(d.data(), d.size());
}

long byte_sum(const Descriptor& d) {
  return std::accumulate(d.begin(), d.end(), 0L);
}

template <class F>
cv::Mat make_image(int rows, int cols, F f) {
  cv::Mat image(rows, cols, CV_8UC1);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) image.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(f(x, y));
  }
  return image;
}

cv::Mat constant_image() {
  return make_image(192, 192, [](int, int) { return 128; });
}
cv::Mat ramp_x() {
  return make_image(192, 192, [](int x, int) { return x; });
}
cv::Mat ramp_y() {
  return make_image(192, 192, [](int, int y) { return y; });
}
cv::Mat pattern() {
  return make_image(192, 192, [](int x, int y) { return (7 * x + 13 * y + 5 * ((x * y) % 17)) % 256; });
}

// The normalisation named `word` (libdird or l2) through the config's name table.
DirdNormalization normalization_named(const std::string& word) {
  for (const EnumName<DirdNormalization>& n : enum_names(DirdNormalization{}))
    if (n.name == word) return n.value;
  throw std::invalid_argument("no dird.normalization " + word);
}

Descriptor extract(const cv::Mat& image, const std::string& normalization = "libdird", bool flip = false) {
  DirdConfig config;
  config.normalization = normalization_named(normalization);
  config.flip_vertical = flip;
  return DirdExtractor(config).extract(image);
}

TEST(DirdExtractor, Md5SelfCheck) {
  EXPECT_EQ(md5_hex(nullptr, 0), "d41d8cd98f00b204e9800998ecf8427e");
  const std::string abc = "abc";
  EXPECT_EQ(md5_hex(reinterpret_cast<const std::uint8_t*>(abc.data()), abc.size()),
            "900150983cd24fb0d6963f7d28e17f72");
}

TEST(DirdExtractor, ConstantImageVector) {
  const Descriptor d = extract(constant_image());
  EXPECT_EQ(byte_sum(d), 345600);
  for (std::uint8_t b : d) ASSERT_EQ(b, 100);
  EXPECT_EQ(md5_hex(d), "1b259a304b29fdd26f2312940adf8961");
}

TEST(DirdExtractor, RampXVectorLibdird) {
  const Descriptor d = extract(ramp_x());
  EXPECT_EQ(byte_sum(d), 348095);
  EXPECT_EQ(md5_hex(d), "d623f58a6ca0344705f652aa2eae144d");
}

TEST(DirdExtractor, RampYVectorLibdird) {
  const Descriptor d = extract(ramp_y());
  EXPECT_EQ(byte_sum(d), 348095);
  EXPECT_EQ(md5_hex(d), "8da987fe0da6006cede7a601f02f4204");
}

TEST(DirdExtractor, PatternVectorLibdird) {
  const Descriptor d = extract(pattern());
  EXPECT_EQ(byte_sum(d), 382435);
  EXPECT_EQ(md5_hex(d), "20d3fadd72143b90709e16f7aa4adcfc");
}

TEST(DirdExtractor, RampXVectorL2) {
  const Descriptor d = extract(ramp_x(), "l2");
  EXPECT_EQ(byte_sum(d), 345629);
  EXPECT_EQ(md5_hex(d), "d92d339b4cf1ccaf5a40ff9c7b1939de");
}

TEST(DirdExtractor, PatternVectorL2) {
  const Descriptor d = extract(pattern(), "l2");
  EXPECT_EQ(byte_sum(d), 382136);
  EXPECT_EQ(md5_hex(d), "526fbe81c561a5fae03710a359886269");
}

TEST(DirdExtractor, HandCheckedBytesRampX) {
  const Descriptor d = extract(ramp_x());
  const std::array<int, 24> tile0_cell4 = {85, 115, 100, 100, 100, 100, 70, 130, 100, 100, 100, 100,
                                           40, 160, 100, 100, 100, 100, 0,  220, 100, 100, 100, 100};
  const std::array<int, 24> tile15_cell8 = {88, 111, 100, 100, 100, 100, 77, 122, 100, 100, 100, 100,
                                            55, 145, 100, 100, 100, 100, 10, 190, 100, 100, 100, 100};
  for (int k = 0; k < 24; ++k) {
    EXPECT_EQ(d[static_cast<std::size_t>(216 * 0 + 24 * 4 + k)], tile0_cell4[static_cast<std::size_t>(k)])
        << k;
    EXPECT_EQ(d[static_cast<std::size_t>(216 * 15 + 24 * 8 + k)], tile15_cell8[static_cast<std::size_t>(k)])
        << k;
  }
}

TEST(DirdExtractor, LowContrastLibdirdZeroesInvalidCells) {
  // Values 0/1 alternating in 2x2 blocks: q stays below 1 everywhere, so libdird marks pixels invalid
  // (d = floor(sqrt(q)) = 0) and their cells become 0; l2 mode has no invalid pixels.
  const cv::Mat image = make_image(192, 192, [](int x, int y) { return ((x / 2 + y / 2) % 2) + 120; });
  const Descriptor libdird = extract(image);
  const Descriptor l2 = extract(image, "l2");
  const long zeros_libdird = std::count(libdird.begin(), libdird.end(), std::uint8_t{0});
  EXPECT_GT(zeros_libdird, 3000);
  EXPECT_EQ(std::count(l2.begin(), l2.end(), std::uint8_t{0}), 0);
}

TEST(DirdExtractor, ColourConversionBt601Rounded) {
  EXPECT_EQ(bt601_grey(255, 255, 255), 255);
  EXPECT_EQ(bt601_grey(0, 0, 0), 0);
  EXPECT_EQ(bt601_grey(255, 0, 0), 76);   // 76.245
  EXPECT_EQ(bt601_grey(0, 255, 0), 150);  // 149.685
  EXPECT_EQ(bt601_grey(0, 0, 255), 29);   // 29.07
  EXPECT_EQ(bt601_grey(10, 20, 30), 18);  // 2.99 + 11.74 + 3.42 = 18.15
  EXPECT_EQ(bt601_grey(1, 1, 2), 1);      // 1.114
  EXPECT_EQ(bt601_grey(0, 1, 4), 1);      // 0.587 + 0.456 = 1.043
  EXPECT_EQ(bt601_grey(3, 0, 0), 1);      // 0.897 -> 1
  EXPECT_EQ(bt601_grey(0, 0, 4), 0);      // 0.456 -> 0

  // A colour image gives the descriptor of its BT.601 grey version (BGR channel order).
  const cv::Mat grey_pattern = pattern();
  cv::Mat colour(192, 192, CV_8UC3);
  cv::Mat grey_of_colour(192, 192, CV_8UC1);
  for (int y = 0; y < 192; ++y) {
    for (int x = 0; x < 192; ++x) {
      const auto r = static_cast<std::uint8_t>((x * 3 + y) % 256);
      const auto g = grey_pattern.at<std::uint8_t>(y, x);
      const auto b = static_cast<std::uint8_t>((x * y) % 256);
      colour.at<cv::Vec3b>(y, x) = cv::Vec3b(b, g, r);
      grey_of_colour.at<std::uint8_t>(y, x) = bt601_grey(r, g, b);
    }
  }
  EXPECT_EQ(extract(colour), extract(grey_of_colour));
  const cv::Mat converted = to_grey_bt601(colour);
  EXPECT_EQ(cv::norm(converted, grey_of_colour, cv::NORM_INF), 0.0);
  cv::Mat bgra;
  cv::Mat channels[4];
  cv::split(colour, channels);
  channels[3] = cv::Mat(192, 192, CV_8UC1, cv::Scalar(7));
  cv::merge(channels, 4, bgra);
  EXPECT_EQ(extract(bgra), extract(grey_of_colour));
}

TEST(DirdExtractor, RejectsBadInput) {
  DirdExtractor extractor;
  EXPECT_THROW(extractor.extract(cv::Mat()), std::invalid_argument);
  EXPECT_THROW(extractor.extract(cv::Mat(10, 10, CV_16UC1, cv::Scalar(0))), std::invalid_argument);
  EXPECT_THROW(extractor.extract(cv::Mat(10, 10, CV_8UC2, cv::Scalar(0))), std::invalid_argument);
}

TEST(DirdExtractor, ResizeRuleNearestNeighbourFloat) {
  // Doubling every pixel gives the same working image, hence the same descriptor.
  const cv::Mat small = pattern();
  cv::Mat doubled(384, 384, CV_8UC1);
  for (int y = 0; y < 384; ++y) {
    for (int x = 0; x < 384; ++x) doubled.at<std::uint8_t>(y, x) = small.at<std::uint8_t>(y / 2, x / 2);
  }
  EXPECT_EQ(extract(doubled), extract(small));

  // KITTI size: work[v][u] = src[int(v * float(376)/192)][int(u * float(1241)/192)].
  const cv::Mat big =
      make_image(376, 1241, [](int x, int y) { return (x * 31 + y * 17 + (x * y) % 7) % 256; });
  const cv::Mat work = dird_working_image(big);
  ASSERT_EQ(work.rows, 192);
  ASSERT_EQ(work.cols, 192);
  const float sx = 1241.0f / 192.0f;
  const float sy = 376.0f / 192.0f;
  for (int v = 0; v < 192; ++v) {
    for (int u = 0; u < 192; ++u) {
      const int r = static_cast<int>(static_cast<float>(v) * sy);
      const int c = static_cast<int>(static_cast<float>(u) * sx);
      ASSERT_EQ(work.at<std::uint8_t>(v, u), big.at<std::uint8_t>(r, c)) << v << "," << u;
    }
  }
  // Spot values of the index rule: u = 191 -> column int(191 * 6.4635415f) = 1234; v = 191 -> row 374.
  EXPECT_EQ(static_cast<int>(191.0f * sx), 1234);
  EXPECT_EQ(static_cast<int>(191.0f * sy), 374);
  // The fast path (no working image) gives the descriptor of the working image.
  EXPECT_EQ(extract(big), extract(work));
  // Smaller than 192 (upsampling) also works.
  const cv::Mat tiny = make_image(32, 64, [](int x, int y) { return (x * 9 + y * 5) % 256; });
  EXPECT_EQ(extract(tiny), extract(dird_working_image(tiny)));
}

TEST(DirdExtractor, FlipVertical) {
  const cv::Mat image = pattern();
  cv::Mat flipped;
  cv::flip(image, flipped, 0);
  EXPECT_EQ(extract(image, "libdird", true), extract(flipped));
  EXPECT_NE(extract(image, "libdird", true), extract(image));
  // A vertical ramp read bottom-up is a descending ramp: the vertical filter changes sign.
  const Descriptor up = extract(ramp_y());
  const Descriptor down = extract(ramp_y(), "libdird", true);
  EXPECT_NE(up, down);
  // Tile 0, centre cell, channel 1 (level 0, vertical): s = -1.5 -> 85 in one, +1.5 -> 115 in the other.
  EXPECT_EQ(up[24 * 4 + 2], 85);
  EXPECT_EQ(down[24 * 4 + 2], 115);
  // Non-square odd size with flip: same as flipping first.
  const cv::Mat odd = make_image(101, 333, [](int x, int y) { return (x * 3 + y * y) % 256; });
  cv::Mat odd_flipped;
  cv::flip(odd, odd_flipped, 0);
  EXPECT_EQ(extract(odd, "l2", true), extract(odd_flipped, "l2"));
}

Descriptor extract_area(const cv::Mat& image, const std::string& normalization = "l2", bool flip = false) {
  DirdConfig config;
  config.normalization = normalization_named(normalization);
  config.flip_vertical = flip;
  config.resize = DirdResize::kArea;
  return DirdExtractor(config).extract(image);
}

TEST(DirdExtractor, AreaResizeIsTheRoundedBlockMean) {
  // 384 x 576: every working pixel covers 2 rows x 3 columns; the block (u, v) holds the values
  // base + {0, 1, 2, 3, 4, 5} with base = (7u + 13v) mod 200: mean base + 2.5, rounded half up to base + 3.
  const auto base = [](int u, int v) { return (7 * u + 13 * v) % 200; };
  const cv::Mat big =
      make_image(384, 576, [&](int x, int y) { return base(x / 3, y / 2) + (y % 2) * 3 + x % 3; });
  const cv::Mat means = make_image(192, 192, [&](int u, int v) { return base(u, v) + 3; });
  for (const char* normalization : {"libdird", "l2"}) {
    EXPECT_EQ(extract_area(big, normalization), extract(means, normalization)) << normalization;
  }
  // Flipped: the same as flipping first. Colour: grey first (BT.601), then the means.
  cv::Mat flipped;
  cv::flip(big, flipped, 0);
  EXPECT_EQ(extract_area(big, "l2", true), extract_area(flipped, "l2"));
  cv::Mat channels[3] = {big, big, big}, colour;
  cv::merge(channels, 3, colour);
  EXPECT_EQ(extract_area(colour), extract_area(big));
  // Smaller than the working image: one source pixel per working pixel (v H / 192 in integers).
  const cv::Mat small = make_image(64, 32, [](int x, int y) { return (x * 5 + y * 11) % 256; });
  const cv::Mat upsampled =
      make_image(192, 192, [&](int u, int v) { return small.at<std::uint8_t>(v * 64 / 192, u * 32 / 192); });
  EXPECT_EQ(extract_area(small), extract(upsampled, "l2"));
}

TEST(DirdExtractor, AreaResizeOfIrregularBlocksIsTheRoundedBlockMeanOfTheRule) {
  // Frame sizes whose blocks are 3 or 4 pixels wide and 1 to 3 rows high (EuRoC 752 x 480, KITTI's 1241 x
  // 376, an odd 333 x 101), noise-like pixels: the working image by the rule, block (u, v) = source rows
  // [v H / 192, max(that + 1, (v + 1) H / 192)) and the same for columns, its mean rounded half up.
  for (const auto& [rows, cols] : {std::pair{480, 752}, std::pair{376, 1241}, std::pair{101, 333}}) {
    const cv::Mat image =
        make_image(rows, cols, [](int x, int y) { return (x * 7919 + y * 104729 + x * y * 31) % 256; });
    const auto block = [](int k, int n) {
      const int lo = k * n / 192;
      return std::pair{lo, std::min(n, std::max(lo + 1, (k + 1) * n / 192))};
    };
    const cv::Mat means = make_image(192, 192, [&](int u, int v) {
      const auto [r0, r1] = block(v, rows);
      const auto [c0, c1] = block(u, cols);
      int sum = 0;
      for (int y = r0; y < r1; ++y) {
        for (int x = c0; x < c1; ++x) sum += image.at<std::uint8_t>(y, x);
      }
      const int count = (r1 - r0) * (c1 - c0);
      return (sum + count / 2) / count;
    });
    for (const char* normalization : {"libdird", "l2"}) {
      EXPECT_EQ(extract_area(image, normalization), extract(means, normalization))
          << rows << " x " << cols << ", " << normalization;
    }
  }
}

TEST(DirdExtractor, AreaResizeAveragesSensorNoiseAway) {
  // A textured 1241 x 376 frame and the same with Gaussian noise of sigma 9 grey levels (the simulator's
  // harsh night): the area working image keeps the descriptor much closer to the clean one.
  cv::Mat clean(376, 1241, CV_8UC1);
  cv::RNG rng(5);
  cv::Mat coarse(24, 80, CV_8UC1);
  rng.fill(coarse, cv::RNG::UNIFORM, 40, 216);
  cv::resize(coarse, clean, clean.size(), 0, 0, cv::INTER_LINEAR);
  cv::Mat noise(clean.size(), CV_16SC1), noisy16;
  rng.fill(noise, cv::RNG::NORMAL, 0, 9);
  clean.convertTo(noisy16, CV_16SC1);
  noisy16 += noise;
  cv::Mat noisy;
  noisy16.convertTo(noisy, CV_8UC1);
  const auto sad = [](const Descriptor& a, const Descriptor& b) {
    int sum = 0;
    for (std::size_t k = 0; k < a.size(); ++k) sum += std::abs(int{a[k]} - int{b[k]});
    return sum;
  };
  const int nearest = sad(extract(clean, "l2"), extract(noisy, "l2"));
  const int area = sad(extract_area(clean), extract_area(noisy));
  std::printf("SAD clean vs noisy: nearest %d, area %d\n", nearest, area);
  EXPECT_LT(area, nearest / 2);
}

TEST(DirdExtractor, DescriptorPictureLayout) {
  Descriptor d{};
  for (std::size_t k = 0; k < d.size(); ++k) d[k] = static_cast<std::uint8_t>(k % 251);
  const cv::Mat picture = descriptor_picture(d);
  ASSERT_EQ(picture.rows, 54);
  ASSERT_EQ(picture.cols, 64);
  EXPECT_EQ(picture.at<std::uint8_t>(0, 63), d[63]);
  EXPECT_EQ(picture.at<std::uint8_t>(1, 0), d[64]);
  EXPECT_EQ(picture.at<std::uint8_t>(53, 63), d[3455]);
}

TEST(DirdExtractor, RealKittiFrameIsDeterministicAndInformative) {
  LOOPGATE_REQUIRE_SHARED_DATA("kitti/00/frames/image_0/000000.png");
  const auto path = testing::shared_data_dir() / "kitti/00/frames/image_0/000000.png";
  const cv::Mat image = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(image.empty());
  ASSERT_EQ(image.cols, 1241);
  ASSERT_EQ(image.rows, 376);
  const Descriptor a = extract(image);
  EXPECT_EQ(a, extract(image));
  EXPECT_EQ(a, extract(dird_working_image(image)));
  // Full-resolution photographs have few invalid pixels: most bytes are non-zero and vary.
  EXPECT_LT(std::count(a.begin(), a.end(), std::uint8_t{0}), 500);
  EXPECT_GT(std::count_if(a.begin(), a.end(), [](std::uint8_t b) { return b != 100; }), 1500);
}

}  // namespace
}  // namespace loopgate
