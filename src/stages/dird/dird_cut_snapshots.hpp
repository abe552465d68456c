// The causal snapshots of a compact coder's cuts (dird_codes.hpp), kept as the change from one snapshot to
// the next. A gated run keeps every snapshot (a past frame described late is coded with the cuts of its own
// time), one per `standardize.refresh_every` frames: 6.9 KB each for ternary codes, 691 MB over a million
// frames. Consecutive snapshots differ little (the statistics' window moves by a tenth of itself), so:
//
// - every kKeyEvery-th snapshot is kept whole (a key);
// - every other one as the difference d[k] = cut[k] - previous cut[k] of each cut byte, in the smallest of
//   these records: exceptions only (d = 0 elsewhere), 2 bits per byte (d in {0, +1, -1}), 4 bits per byte
//   (d in -7..7), a Rice code of zigzag(d) with parameter 0..3 (most d are small, few are large), or the
//   bytes themselves. A byte whose d the record cannot hold is an exception: its index and new value
//   after the packed part.
//
// Reading snapshot i decodes from the key before it (at most kKeyEvery - 1 records), or from the last one
// read when it lies between that key and i: frames are mostly coded in order (a candidate area is a run of
// consecutive frames), so most reads apply one record or none. The latest snapshot, the one a frame coded
// at its own time uses, is kept whole. Lossless: cuts(i) returns the bytes push() was given.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace loopgate {

class CutSnapshots {
 public:
  static constexpr std::size_t kKeyEvery = 16;

  // Snapshots of `cut_bytes` bytes each (1 to 65 535).
  explicit CutSnapshots(std::size_t cut_bytes);

  // Appends a snapshot (cut_bytes bytes).
  void push(const std::uint8_t* cuts);
  // Snapshot `index`'s bytes, valid until the next push() or cuts(). Throws std::out_of_range.
  const std::uint8_t* cuts(std::size_t index);

  std::size_t size() const { return offsets_.size(); }
  // Bytes held for the snapshots: the records, their index and the two whole snapshots kept decoded.
  std::size_t bytes() const;

 private:
  void append_record(const std::vector<std::uint8_t>& record);
  const std::uint8_t* record(std::size_t index) const;
  void apply(std::size_t index, std::uint8_t* cuts) const;

  std::size_t cut_bytes_;
  std::vector<std::unique_ptr<std::uint8_t[]>> chunks_;  // records, never split over two chunks
  std::size_t used_in_last_chunk_ = 0;
  std::size_t record_bytes_ = 0;
  std::vector<std::uint64_t> offsets_;  // chunk * kChunkBytes + offset of each record
  std::vector<std::uint8_t> latest_;    // the last snapshot pushed, whole
  std::vector<std::uint8_t> decoded_;   // the last snapshot read, whole
  std::size_t decoded_index_ = 0;
  bool decoded_valid_ = false;
  std::vector<std::uint8_t> scratch_;  // the record being built
};

}  // namespace loopgate
