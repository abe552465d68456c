#include "eval/loop_files.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>

#include "core/error.hpp"

namespace loopgate {

namespace {

// A UTF-8 byte-order mark (Windows editors write one) before the first line is no part of its text: without
// this, a header-less file's first row would start with a non-digit and be taken for a header.
void strip_bom(std::string& line, std::size_t line_no) {
  if (line_no == 1 && line.rfind("\xEF\xBB\xBF", 0) == 0) line.erase(0, 3);
}

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
    strip_bom(line, line_no);
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

TruthPairs read_truth_pairs(const std::filesystem::path& file, std::optional<std::size_t> frame_count) {
  std::error_code ec;
  if (std::filesystem::exists(file, ec) && !std::filesystem::is_regular_file(file, ec))
    throw DataError(file, "not a regular file (a FIFO, socket, device or directory), expected a pairs file");
  std::ifstream in(file);
  if (!in) throw DataError(file, "cannot open the loop ground-truth pairs file");
  TruthPairs out;
  std::string line;
  std::size_t line_no = 0;
  bool first_row = true;
  while (std::getline(in, line)) {
    ++line_no;
    strip_bom(line, line_no);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto begin = line.find_first_not_of(" \t");
    if (begin == std::string::npos || line[begin] == '#') continue;
    // The first two fields: comma-separated when the line has a comma, else blank-separated; trimmed.
    std::vector<std::string> fields;
    const bool commas = line.find(',') != std::string::npos;
    std::size_t pos = begin;
    while (fields.size() < 2 && pos <= line.size()) {
      const std::size_t end = commas ? line.find(',', pos) : line.find_first_of(" \t", pos);
      std::string field = line.substr(pos, end == std::string::npos ? std::string::npos : end - pos);
      const auto a = field.find_first_not_of(" \t");
      const auto b = field.find_last_not_of(" \t");
      fields.push_back(a == std::string::npos ? std::string{} : field.substr(a, b - a + 1));
      if (end == std::string::npos) break;
      pos = commas ? end + 1 : line.find_first_not_of(" \t", end);
      if (pos == std::string::npos) break;
    }
    const auto index = [&](const std::string& text, std::optional<std::size_t>* value) {
      std::size_t v = 0;
      const auto [ptr, err] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (err == std::errc{} && ptr == text.data() + text.size() && !text.empty()) *value = v;
    };
    std::optional<std::size_t> query, reference;
    if (!fields.empty()) index(fields[0], &query);
    if (fields.size() > 1) index(fields[1], &reference);
    const bool words = !fields.empty() && !fields[0].empty() &&
                       std::string_view("0123456789+-.").find(fields[0][0]) == std::string_view::npos;
    if (first_row && words) {  // a header ("query_index0,match_index0,...")
      first_row = false;
      continue;
    }
    first_row = false;
    if (!query || !reference) {
      throw DataError(
          file, line_no,
          "expected two 0-based frame numbers (query, reference) separated by ',' or blanks, got " +
              quote_excerpt(line));
    }
    if (*query == *reference) {
      throw DataError(file, line_no,
                      "frame " + std::to_string(*query) + " is paired with itself; a loop joins two frames");
    }
    for (const std::size_t f : {*query, *reference}) {
      if (frame_count && f >= *frame_count) {
        throw DataError(file, line_no,
                        "frame " + std::to_string(f) +
                            " is not a frame of the dataset (its frames are numbered 0.." +
                            std::to_string(*frame_count == 0 ? 0 : *frame_count - 1) +
                            "): pairs of another sequence, or 1-based numbers?");
      }
    }
    ++out.rows;
    out.pairs.emplace_back(std::max(*query, *reference), std::min(*query, *reference));
  }
  std::sort(out.pairs.begin(), out.pairs.end());
  out.pairs.erase(std::unique(out.pairs.begin(), out.pairs.end()), out.pairs.end());
  return out;
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
