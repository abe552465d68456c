// loops.csv, the same file for every run (single sequence, two sequences, every method): one loop closure per
// row, i (current / query frame), j (earlier / reference frame), their times in s and the method's score.
// write() takes dataset frame indices; the file shows the frames' numbers (Dataset::source_index, through the
// labels given to open(): a rejected input row leaves a gap, it does not renumber the later frames). It also
// keeps the loops written (dataset frame indices), for the evaluation.
#pragma once

#include <cstddef>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/types.hpp"
#include "eval/precision_recall.hpp"
#include "io/writers.hpp"

namespace loopgate {

class LoopsWriter {
 public:
  using Label = std::function<std::size_t(std::size_t)>;  // dataset frame index -> the frame's number
  // Without labels the file shows dataset frame indices.
  void open(const std::filesystem::path& file, Label label_i = {}, Label label_j = {});
  bool is_open() const { return csv_.is_open(); }
  void write(std::size_t frame_i, std::size_t frame_j, Timestamp t_i_ns, Timestamp t_j_ns, double score);
  void flush() { csv_.flush(); }
  void close();
  // Called with every loop as it is written (the loop closer's queue; set before the run starts).
  void set_listener(std::function<void(const Detection&)> listener) { listener_ = std::move(listener); }
  // After close(): writes the file again with `columns` appended to every row, `cells(k)` giving loop k's.
  void rewrite_with(const std::vector<std::string>& columns,
                    const std::function<std::vector<std::string>(std::size_t)>& cells);

  // Every loop written, (i, j, score) in dataset frame indices.
  const std::vector<Detection>& loops() const { return loops_; }
  std::size_t count() const { return loops_.size(); }

 private:
  CsvWriter csv_;
  Label label_i_, label_j_;
  std::vector<Detection> loops_;
  std::vector<std::vector<std::string>> rows_;  // the cells written, for rewrite_with()
  std::filesystem::path file_;
  std::function<void(const Detection&)> listener_;
};

}  // namespace loopgate
