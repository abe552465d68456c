#include "stages/dird/dird_extractor.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

namespace loopgate {

namespace {

// The constants of the DIRD extraction (docs/detection.md § DIRD).
constexpr int kTiles = 4;
constexpr int kTileSize = 48;
constexpr int kLevels = 4;
constexpr int kFilters = 3;
constexpr int kChannels = kLevels * kFilters;  // channel c = 3 * level + filter
constexpr int kBandLo = 8;                     // responses exist for kBandLo <= x, y < kBandHi
constexpr int kBandHi = kDirdWorkingSize - 8;
constexpr double kNormalisationGuard = 0.001;
constexpr int kCellsPerSide = 3;
constexpr int kCells = kCellsPerSide * kCellsPerSide;
constexpr int kCellSpacing = 13;
constexpr int kSamplesPerCell = 12;
constexpr int kFineOffsets[kSamplesPerCell][2] = {{0, 0},  {-3, 0}, {-2, -2}, {-1, -3},
                                                  {2, -2}, {5, 0},  {-1, 1},  {0, 1},
                                                  {2, 1},  {2, 2},  {-1, 3},  {-1, 5}};  // (dy, dx)
constexpr int kBytesPerCell = kChannels * 2;
constexpr int kBytesPerTile = kCells * kBytesPerCell;  // 216
constexpr double kQuantScale = 10.0;
constexpr double kQuantOffset = 100.0;
static_assert(kTiles * kTiles * kBytesPerTile == static_cast<int>(kDirdBytes));
static_assert(kDirdPictureRows * kDirdPictureCols == static_cast<int>(kDirdBytes));

constexpr int kSide = kDirdWorkingSize;

// Per-thread scratch: the inclusive integral image of the working image (int32 is exact here: the
// largest sum is 255 * 192 * 192 < 2^24).
struct Workspace {
  std::vector<std::int32_t> integral = std::vector<std::int32_t>(static_cast<std::size_t>(kSide * kSide));
  std::vector<std::uint32_t> column_sums;  // build_area_integral: one block row's sum per source column
};

Workspace& thread_workspace() {
  thread_local Workspace workspace;
  return workspace;
}

void check_input(const cv::Mat& image) {
  if (image.empty()) throw std::invalid_argument("DIRD: empty image");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)) {
    throw std::invalid_argument("DIRD: expected an 8-bit grey, BGR or BGRA image, got type " +
                                std::to_string(image.type()));
  }
}

// Nearest-neighbour source index tables (docs/detection.md § DIRD, 32-bit float arithmetic).
void source_indices(const cv::Mat& image, bool flip_vertical, int* rows, int* cols) {
  const float sx = static_cast<float>(image.cols) / static_cast<float>(kSide);
  const float sy = static_cast<float>(image.rows) / static_cast<float>(kSide);
  for (int k = 0; k < kSide; ++k) {
    const int r = static_cast<int>(static_cast<float>(k) * sy);
    rows[k] = flip_vertical ? image.rows - 1 - r : r;
    cols[k] = static_cast<int>(static_cast<float>(k) * sx);
  }
}

template <int kCn>
inline std::uint8_t grey_at(const std::uint8_t* row, int col) {
  if constexpr (kCn == 1) {
    return row[col];
  } else {
    const std::uint8_t* px = row + static_cast<std::ptrdiff_t>(col) * kCn;
    return bt601_grey(px[2], px[1], px[0]);
  }
}

template <int kCn>
void build_integral(const cv::Mat& image, const int* rows, const int* cols, std::int32_t* integral) {
  for (int v = 0; v < kSide; ++v) {
    const std::uint8_t* src = image.ptr<std::uint8_t>(rows[v]);
    std::int32_t* out = integral + v * kSide;
    const std::int32_t* above = v > 0 ? out - kSide : nullptr;
    std::int32_t row_sum = 0;
    for (int u = 0; u < kSide; ++u) {
      row_sum += grey_at<kCn>(src, cols[u]);
      out[u] = above != nullptr ? row_sum + above[u] : row_sum;
    }
  }
}

// dird.resize area: the working image as block means of the grey image (integer arithmetic, rounded),
// then its integral. Block of working row v: source rows [v H / 192, max(that + 1, (v + 1) H / 192)), the
// same for columns.
void build_area_integral(const cv::Mat& grey, bool flip_vertical, std::int32_t* integral,
                         std::vector<std::uint32_t>& column_sums) {
  const auto block = [](int k, int n) {
    const int lo = static_cast<int>(static_cast<std::int64_t>(k) * n / kSide);
    const int hi = std::max(lo + 1, static_cast<int>(static_cast<std::int64_t>(k + 1) * n / kSide));
    return std::pair{lo, std::min(hi, n)};
  };
  int c_lo[kSide], c_hi[kSide];
  for (int u = 0; u < kSide; ++u) std::tie(c_lo[u], c_hi[u]) = block(u, grey.cols);
  // A block row's rows are first added column by column (a loop the compiler vectorises: blocks are 3 or 4
  // pixels wide on a 752-pixel image, too short to vectorise on their own), then each block adds its
  // columns. Integer sums: the same block sums, in any order, as adding the block's pixels one by one.
  column_sums.resize(static_cast<std::size_t>(grey.cols));
  std::uint32_t* columns = column_sums.data();
  const int cols = grey.cols;
  for (int v = 0; v < kSide; ++v) {
    const auto [r0, r1] = block(v, grey.rows);
    std::fill(columns, columns + cols, 0u);
    for (int r = r0; r < r1; ++r) {
      const std::uint8_t* src = grey.ptr<std::uint8_t>(flip_vertical ? grey.rows - 1 - r : r);
      for (int c = 0; c < cols; ++c) columns[c] += src[c];
    }
    std::int32_t* out = integral + v * kSide;
    const std::int32_t* above = v > 0 ? out - kSide : nullptr;
    std::int32_t row_sum = 0;
    const auto rows = static_cast<std::uint32_t>(r1 - r0);
    for (int u = 0; u < kSide; ++u) {
      std::uint32_t sum = 0;
      for (int c = c_lo[u]; c < c_hi[u]; ++c) sum += columns[c];
      const std::uint32_t count = rows * static_cast<std::uint32_t>(c_hi[u] - c_lo[u]);
      row_sum += static_cast<std::int32_t>((sum + count / 2) / count);
      out[u] = above != nullptr ? row_sum + above[u] : row_sum;
    }
  }
}

inline std::uint8_t quantise(double s) {
  const double value = kQuantScale * s + kQuantOffset;
  if (!(value > 0.0)) return 0;
  if (value >= 255.0) return 255;
  return static_cast<std::uint8_t>(value);  // truncation toward zero
}

// Responses of one pixel (docs/detection.md § DIRD). Returns false for an invalid pixel (libdird mode).
inline bool pixel_responses(const std::int32_t* integral, int x, int y, bool l2_normalization,
                            double* responses) {
  if (x < kBandLo || x >= kBandHi || y < kBandLo || y >= kBandHi) {
    std::fill(responses, responses + kChannels, 0.0);
    return true;
  }
  double q = 0.0;
  for (int level = 0; level < kLevels; ++level) {
    const int h = 1 << level;
    const double area = static_cast<double>(4 * h * h);
    const std::int32_t* r0 = integral + (y - h) * kSide;
    const std::int32_t* r1 = integral + y * kSide;
    const std::int32_t* r2 = integral + (y + h) * kSide;
    const std::int64_t p00 = r0[x - h], p01 = r0[x], p02 = r0[x + h];
    const std::int64_t p10 = r1[x - h], p11 = r1[x], p12 = r1[x + h];
    const std::int64_t p20 = r2[x - h], p21 = r2[x], p22 = r2[x + h];
    const std::int64_t left = p21 - p01 - p20 + p00;
    const std::int64_t right = p22 - p02 - p21 + p01;
    const std::int64_t top = p12 - p02 - p10 + p00;
    const std::int64_t bottom = p22 - p12 - p20 + p10;
    const std::int64_t top_left = p11 - p01 - p10 + p00;
    const std::int64_t bottom_right = p22 - p12 - p21 + p11;
    const std::int64_t top_right = p12 - p02 - p11 + p01;
    const std::int64_t bottom_left = p21 - p11 - p20 + p10;
    const double f0 = static_cast<double>(left - right) / area;
    const double f1 = static_cast<double>(top - bottom) / area;
    const double f2 = static_cast<double>(top_left + bottom_right - top_right - bottom_left) / area;
    responses[3 * level + 0] = f0;
    responses[3 * level + 1] = f1;
    responses[3 * level + 2] = f2;
    q += f0 * f0 + f1 * f1 + f2 * f2;
  }
  if (q > kNormalisationGuard) {
    const double divisor = l2_normalization ? std::sqrt(q) : std::floor(std::sqrt(q));
    if (divisor == 0.0) return false;  // libdird: the reference divides by zero here
    for (int c = 0; c < kChannels; ++c) responses[c] /= divisor;
  }
  return true;
}

void extract_from_integral(const std::int32_t* integral, bool l2_normalization, Descriptor& out) {
  double responses[kSamplesPerCell][kChannels];
  for (int tx = 0; tx < kTiles; ++tx) {
    for (int ty = 0; ty < kTiles; ++ty) {
      const int tile = kTiles * tx + ty;
      const int u = kTileSize * tx + kTileSize / 2;
      const int v = kTileSize * ty + kTileSize / 2;
      for (int ix = 0; ix < kCellsPerSide; ++ix) {
        for (int iy = 0; iy < kCellsPerSide; ++iy) {
          const int cell = kCellsPerSide * ix + iy;
          const int dx = kCellSpacing * (ix - 1);
          const int dy = kCellSpacing * (iy - 1);
          bool valid = true;
          for (int k = 0; k < kSamplesPerCell; ++k) {
            const int y = v + dy + kFineOffsets[k][0];
            const int x = u + dx + kFineOffsets[k][1];
            valid = pixel_responses(integral, x, y, l2_normalization, responses[k]) && valid;
          }
          std::uint8_t* cell_out = out.data() + kBytesPerTile * tile + kBytesPerCell * cell;
          if (!valid) {
            std::fill(cell_out, cell_out + kBytesPerCell, std::uint8_t{0});
            continue;
          }
          for (int c = 0; c < kChannels; ++c) {
            double s = 0.0;
            double a = 0.0;
            for (int k = 0; k < kSamplesPerCell; ++k) {
              s += responses[k][c];
              a += std::fabs(responses[k][c]);
            }
            cell_out[2 * c] = quantise(s);
            cell_out[2 * c + 1] = quantise(a);
          }
        }
      }
    }
  }
}

}  // namespace

cv::Mat to_grey_bt601(const cv::Mat& image) {
  check_input(image);
  if (image.channels() == 1) return image.clone();
  cv::Mat grey(image.rows, image.cols, CV_8UC1);
  const int cn = image.channels();
  for (int r = 0; r < image.rows; ++r) {
    const std::uint8_t* src = image.ptr<std::uint8_t>(r);
    std::uint8_t* dst = grey.ptr<std::uint8_t>(r);
    for (int c = 0; c < image.cols; ++c) {
      const std::uint8_t* px = src + static_cast<std::ptrdiff_t>(c) * cn;
      dst[c] = bt601_grey(px[2], px[1], px[0]);
    }
  }
  return grey;
}

cv::Mat dird_working_image(const cv::Mat& image, bool flip_vertical) {
  const cv::Mat grey = to_grey_bt601(image);
  int rows[kSide];
  int cols[kSide];
  source_indices(grey, flip_vertical, rows, cols);
  cv::Mat work(kSide, kSide, CV_8UC1);
  for (int v = 0; v < kSide; ++v) {
    for (int u = 0; u < kSide; ++u) work.at<std::uint8_t>(v, u) = grey.at<std::uint8_t>(rows[v], cols[u]);
  }
  return work;
}

DirdExtractor::DirdExtractor(const DirdConfig& config) : config_(config) {
  config_.validate();
  l2_normalization_ = config_.l2_normalization();
}

Descriptor DirdExtractor::extract(const cv::Mat& image) const {
  Descriptor out;
  extract(image, out);
  return out;
}

void DirdExtractor::extract(const cv::Mat& image, Descriptor& out) const {
  check_input(image);
  if (config_.area_resize()) {
    Workspace& workspace = thread_workspace();
    std::int32_t* integral = workspace.integral.data();
    if (image.channels() == 1) {
      build_area_integral(image, config_.flip_vertical, integral, workspace.column_sums);
    } else {
      build_area_integral(to_grey_bt601(image), config_.flip_vertical, integral, workspace.column_sums);
    }
    extract_from_integral(integral, l2_normalization_, out);
    return;
  }
  int rows[kSide];
  int cols[kSide];
  source_indices(image, config_.flip_vertical, rows, cols);
  std::int32_t* integral = thread_workspace().integral.data();
  switch (image.channels()) {
    case 1: build_integral<1>(image, rows, cols, integral); break;
    case 3: build_integral<3>(image, rows, cols, integral); break;
    default: build_integral<4>(image, rows, cols, integral); break;
  }
  extract_from_integral(integral, l2_normalization_, out);
}

cv::Mat descriptor_picture(const Descriptor& descriptor) {
  cv::Mat picture(kDirdPictureRows, kDirdPictureCols, CV_8UC1);
  std::copy(descriptor.begin(), descriptor.end(), picture.ptr<std::uint8_t>(0));
  return picture;
}

}  // namespace loopgate
