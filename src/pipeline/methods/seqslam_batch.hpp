// SeqSLAM as a method of the pipeline (`run.method: seqslam`, docs/detection.md § SeqSLAM): the describe node
// preprocesses every frame (step 1, in parallel, stored by sequence number); at the end of the stream the
// difference matrix, the contrast enhancement and the sequence search (steps 2-4) run over the whole run
// in parallel blocks (single-sequence: reference = query = the run, with the configured exclusion;
// two-sequence mode: run_two_sequence() over a reference and a query sequence held in one store).
// SeqSLAM needs the frames on both sides of a query (ds/2 later ones) and the statistics of its
// neighbouring reference rows, so it is a batch method: its results are known when the stream ends.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <opencv2/core/mat.hpp>
#include <vector>

#include "stages/seqslam/seqslam.hpp"

namespace loopgate {

class SeqSlamBatch {
 public:
  // `capacity`: frames the run may release. Validates the config (ConfigError).
  SeqSlamBatch(const SeqSlamConfig& config, std::size_t capacity);

  // Step 1 for frame `seq` (thread-safe for distinct seqs). Throws std::invalid_argument for an image
  // the preprocessing cannot take (wrong pixel type, or a preprocessed input of the wrong size).
  void add(std::size_t seq, const cv::Mat& image);
  // Frame `seq` has no image (it did not decode): it takes part as an all-zero image (no place looks like
  // it), like the zero images of the authors' setup.
  void add_missing(std::size_t seq);

  // Steps 2-4 over frames [0, count) (count <= capacity, every one added), one match per frame, with
  // tbb::parallel_for over blocks of query columns (call it inside the run's task arena).
  // `differences_computed` (optional): the difference-matrix entries computed (the excluded ones are not).
  std::vector<SeqSlamMatch> run(std::size_t count, std::size_t* differences_computed = nullptr) const;

  // Two sequences in one store (two_sequence.hpp): frames [0, reference_count) are the reference
  // sequence, frames [reference_count, reference_count + query_count) the query sequence (every one
  // added). Steps 2-4 with the reference as rows and the query as columns, the configured exclusion
  // applied to (reference index, query index) (two different runs: "none"); one match per query frame,
  // SeqSlamMatch::query and ::reference being indices within their own sequence. Parallel as run().
  std::vector<SeqSlamMatch> run_two_sequence(std::size_t reference_count, std::size_t query_count) const;

  const SeqSlamConfig& config() const { return seqslam_.config(); }
  std::size_t pixel_count() const { return pixel_count_; }
  // The preprocessed pixels of frame `seq` (pixel_count() bytes; meaningful once added).
  const std::uint8_t* image(std::size_t seq) const { return bytes_.get() + seq * pixel_count_; }

 private:
  // Frames [first, first + count) of the store as a set of images.
  SeqSlamImages images(std::size_t first, std::size_t count) const;
  // Steps 2-4 of `query` columns against `reference` rows, in parallel blocks of query columns.
  std::vector<SeqSlamMatch> search(const SeqSlamImages& reference, const SeqSlamImages& query,
                                   std::size_t* differences_computed = nullptr) const;

  SeqSlam seqslam_;
  std::size_t capacity_;
  std::size_t pixel_count_;
  std::unique_ptr<std::uint8_t[]> bytes_;  // capacity x pixel_count, committed as frames are written
};

}  // namespace loopgate
