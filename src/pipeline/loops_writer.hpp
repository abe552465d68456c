// loops.csv, the same file for every run (single sequence, two sequences, every method): one loop closure per
// row, i (current / query frame), j (earlier / reference frame), their times in s and the method's score,
// dataset frame indices. It also keeps the loops written, for the evaluation.
#pragma once

#include <cstddef>
#include <filesystem>
#include <vector>

#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "io/writers.hpp"

namespace loopgate {

class LoopsWriter {
 public:
  void open(const std::filesystem::path& file);
  bool is_open() const { return csv_.is_open(); }
  void write(std::size_t frame_i, std::size_t frame_j, Timestamp t_i_ns, Timestamp t_j_ns, double score);
  void flush() { csv_.flush(); }
  void close();

  // Every loop written, (i, j, score) in dataset frame indices.
  const std::vector<Detection>& loops() const { return loops_; }
  std::size_t count() const { return loops_.size(); }

 private:
  CsvWriter csv_;
  std::vector<Detection> loops_;
};

}  // namespace loopgate
