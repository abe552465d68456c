#include "pipeline/loops_writer.hpp"

#include <string>

namespace loopgate {

void LoopsWriter::open(const std::filesystem::path& file) {
  csv_.open(file, {"i", "j", "t_i", "t_j", "score"});
}

void LoopsWriter::write(std::size_t frame_i, std::size_t frame_j, Timestamp t_i_ns, Timestamp t_j_ns,
                        double score) {
  csv_.write_row({std::to_string(frame_i), std::to_string(frame_j), format_fixed(ns_to_s(t_i_ns), 9),
                  format_fixed(ns_to_s(t_j_ns), 9), format_fixed(score, 6)});
  loops_.push_back(Detection{frame_i, frame_j, score});
}

void LoopsWriter::close() {
  if (csv_.is_open()) csv_.close();
}

}  // namespace loopgate
