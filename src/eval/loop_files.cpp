#include "eval/loop_files.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>

#include "core/error.hpp"

namespace loopgate {

namespace {

// Reads rows of exactly `columns` comma-separated numbers ("nan" allowed); calls row(values, line_no).
template <class RowFn>
void read_numeric_csv(const std::filesystem::path& file, std::size_t columns, RowFn&& row) {
  // A FIFO or a device would block open() or never end (issue 15).
  std::error_code ec;
  if (std::filesystem::exists(file, ec) && !std::filesystem::is_regular_file(file, ec))
    throw DataError(file, "not a regular file (a FIFO, socket, device or directory), expected a csv file");
  std::ifstream in(file);
  if (!in) throw DataError(file, "cannot open file");
  std::string line;
  std::size_t line_no = 0;
  std::vector<double> values;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    values.clear();
    const char* p = line.c_str();
    while (true) {
      char* end = nullptr;
      errno = 0;
      const double v = std::strtod(p, &end);
      if (end == p || errno == ERANGE) {
        throw DataError(
            file, line_no,
            "expected " + std::to_string(columns) + " comma-separated numbers, got " + quote_excerpt(line));
      }
      values.push_back(v);
      p = end;
      while (*p == ' ' || *p == '\t') ++p;
      if (*p == '\0') break;
      if (*p != ',') throw DataError(file, line_no, "expected ',' in '" + line + "'");
      ++p;
    }
    if (values.size() != columns) {
      throw DataError(
          file, line_no,
          "expected " + std::to_string(columns) + " columns, got " + std::to_string(values.size()));
    }
    row(values, line_no);
  }
}

std::size_t to_index(double v, std::size_t base, const std::filesystem::path& file, std::size_t line_no) {
  if (!std::isfinite(v) || v != std::floor(v) || v < static_cast<double>(base)) {
    throw DataError(file, line_no,
                    "expected a frame index >= " + std::to_string(base) + ", got " + std::to_string(v));
  }
  return static_cast<std::size_t>(v) - base;
}

constexpr std::size_t kZeroBased = 0;
constexpr std::size_t kOneBased = 1;

}  // namespace

std::vector<std::pair<std::size_t, std::size_t>> read_loop_pairs(const std::filesystem::path& file) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  read_numeric_csv(file, 2, [&](const std::vector<double>& v, std::size_t line) {
    pairs.emplace_back(to_index(v[0], kZeroBased, file, line), to_index(v[1], kZeroBased, file, line));
  });
  return pairs;
}

std::vector<std::pair<std::size_t, std::size_t>> read_vio_dird_true_loops(const std::filesystem::path& file,
                                                                          std::size_t frame_offset) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  read_numeric_csv(file, 2, [&](const std::vector<double>& v, std::size_t line) {
    const std::size_t earlier = to_index(v[0], kOneBased, file, line);
    const std::size_t current = to_index(v[1], kOneBased, file, line);
    pairs.emplace_back(current + frame_offset, earlier + frame_offset);
  });
  return pairs;
}

std::vector<ReferenceMatch> read_vio_dird_seqslam_matches(const std::filesystem::path& file) {
  std::vector<ReferenceMatch> matches;
  read_numeric_csv(file, 2, [&](const std::vector<double>& v, std::size_t line) {
    ReferenceMatch m;
    if (!std::isnan(v[0])) {
      m.has_match = true;
      m.reference = to_index(v[0], kOneBased, file, line);
      if (std::isnan(v[1])) throw DataError(file, line, "a match without a ratio");
      m.ratio = v[1];
    }
    matches.push_back(m);
  });
  return matches;
}

std::vector<Detection> read_vio_dird_detections(const std::filesystem::path& file, std::size_t frame_offset) {
  std::vector<Detection> detections;
  read_numeric_csv(file, 3, [&](const std::vector<double>& v, std::size_t line) {
    Detection d;
    d.reference = to_index(v[0], kOneBased, file, line) + frame_offset;
    d.query = to_index(v[1], kOneBased, file, line) + frame_offset;
    d.score = v[2];
    if (!std::isfinite(d.score)) throw DataError(file, line, "expected a finite score");
    detections.push_back(d);
  });
  return detections;
}

std::vector<Eigen::Vector3d> read_vio_dird_positions(const std::filesystem::path& file) {
  std::vector<Eigen::Vector3d> positions;
  read_numeric_csv(file, 3, [&](const std::vector<double>& v, std::size_t line) {
    const Eigen::Vector3d p(v[0], v[1], v[2]);
    if (!p.allFinite()) throw DataError(file, line, "expected finite x,y,z");
    positions.push_back(p);
  });
  return positions;
}

}  // namespace loopgate
