// Readers for loop ground-truth and reference-result files: the pairs files
// (../shared/data/*/loops-gt/botw_pairs.csv, "query,reference", 0-based) and the paper's authors'
// outputs in ../shared/data/reference/vio-dird/ (1-based MATLAB indices, "nan" where empty).
// Lines starting with '#' and blank lines are skipped. Every reader converts to 0-based indices and
// throws DataError naming the file and line on a malformed row.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <utility>
#include <vector>

#include "eval/precision_recall.hpp"

namespace loopgate {

// botw_pairs.csv: (query, reference) pairs, 0-based.
std::vector<std::pair<std::size_t, std::size_t>> read_loop_pairs(const std::filesystem::path& file);

// eval.truth_pairs_file: loop ground truth as published for KITTI, EuRoC, RTAB-Map's samples and others, one
// (query, reference) pair of 0-based frame numbers per line. Fields separated by commas or blanks; further
// columns (file names) are ignored; the first data line may be a header (its first field not a number); '#'
// comments and blank lines are skipped. A pair is stored as (later, earlier) frame (a file listing both (i,
// j) and (j, i) of a symmetric matrix gives one pair), duplicates once. DataError names the file and line: a
// field that is not a frame number, a frame paired with itself, or (with `frame_count`) a frame number >= it.
struct TruthPairs {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;  // (query, reference), query > reference, sorted
  std::size_t rows = 0;                                    // data rows read (before removing duplicates)
};
TruthPairs read_truth_pairs(const std::filesystem::path& file, std::optional<std::size_t> frame_count = {});

// kitti00_true_loops*.csv, mh05_true_loops.csv: "earlier,current" 1-based -> (query = current - 1 +
// frame_offset, reference = earlier - 1 + frame_offset). mh05_true_loops.csv indexes the authors'
// slice starting at cam0 frame 401 (1-based): frame_offset = 400 gives 0-based cam0 frames.
std::vector<std::pair<std::size_t, std::size_t>> read_vio_dird_true_loops(const std::filesystem::path& file,
                                                                          std::size_t frame_offset = 0);

// seqslam_kitti00_matches.csv: row k (1-based query k) = "matched frame (1-based or nan), ratio".
struct ReferenceMatch {
  bool has_match = false;
  std::size_t reference = 0;  // 0-based
  double ratio = 0.0;
};
std::vector<ReferenceMatch> read_vio_dird_seqslam_matches(const std::filesystem::path& file);

// dird_mh05_loops_margin*.csv: "i,j,score" 1-based with i < j -> Detection{query = j - 1 + frame_offset,
// reference = i - 1 + frame_offset, score}.
std::vector<Detection> read_vio_dird_detections(const std::filesystem::path& file,
                                                std::size_t frame_offset = 0);

// msckf_mh05_positions.csv: one "x,y,z" row per image.
std::vector<Eigen::Vector3d> read_vio_dird_positions(const std::filesystem::path& file);

}  // namespace loopgate
