#include "stages/dird/dird_cut_snapshots.hpp"

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>

namespace loopgate {

namespace {

constexpr std::size_t kChunkBytes = std::size_t{1} << 20;
constexpr std::size_t kHeaderBytes = 3;     // packed width in bits, then the exception count (uint16)
constexpr std::size_t kExceptionBytes = 3;  // index (uint16), new value

void put_u16(std::uint8_t* p, std::size_t v) {
  p[0] = static_cast<std::uint8_t>(v & 0xff);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}

std::size_t get_u16(const std::uint8_t* p) {
  return static_cast<std::size_t>(p[0]) | (static_cast<std::size_t>(p[1]) << 8);
}

// The packed symbol of difference d at `bits` per byte, or -1 when d is an exception at that width.
// 2 bits: 0 -> 0, +1 -> 1, -1 -> 2. 4 bits: d + 8 for d in -7..7 (0 unused).
int symbol(int d, int bits) {
  if (bits == 0) return d == 0 ? 0 : -1;
  if (bits == 2) return d == 0 ? 0 : (d == 1 ? 1 : (d == -1 ? 2 : -1));
  return (d >= -7 && d <= 7) ? d + 8 : -1;
}

}  // namespace

CutSnapshots::CutSnapshots(std::size_t cut_bytes) : cut_bytes_(cut_bytes) {
  if (cut_bytes == 0 || cut_bytes > 0xffff)
    throw std::invalid_argument("CutSnapshots: cut_bytes must be in [1, 65535]");
  latest_.resize(cut_bytes);
  decoded_.resize(cut_bytes);
}

void CutSnapshots::push(const std::uint8_t* cuts) {
  scratch_.clear();
  if (offsets_.size() % kKeyEvery == 0) {
    scratch_.resize(kHeaderBytes + cut_bytes_);
    scratch_[0] = 8;
    put_u16(scratch_.data() + 1, 0);
    std::memcpy(scratch_.data() + kHeaderBytes, cuts, cut_bytes_);
  } else {
    // The smallest record: count the exceptions of each width.
    std::size_t exceptions[3] = {0, 0, 0};  // 0, 2, 4 bits
    for (std::size_t k = 0; k < cut_bytes_; ++k) {
      const int d = static_cast<int>(cuts[k]) - static_cast<int>(latest_[k]);
      for (int w = 0; w < 3; ++w) exceptions[w] += symbol(d, 2 * w) < 0 ? 1 : 0;
    }
    int bits = 8;
    std::size_t best = cut_bytes_;
    for (int w = 0; w < 3; ++w) {
      const std::size_t size = (cut_bytes_ * 2 * w + 7) / 8 + exceptions[w] * kExceptionBytes;
      if (size < best && exceptions[w] <= 0xffff) best = size, bits = 2 * w;
    }
    scratch_.assign(kHeaderBytes + best, 0);
    scratch_[0] = static_cast<std::uint8_t>(bits);
    if (bits == 8) {
      put_u16(scratch_.data() + 1, 0);
      std::memcpy(scratch_.data() + kHeaderBytes, cuts, cut_bytes_);
    } else {
      std::uint8_t* packed = scratch_.data() + kHeaderBytes;
      std::uint8_t* exception = packed + (cut_bytes_ * static_cast<std::size_t>(bits) + 7) / 8;
      std::size_t n = 0;
      for (std::size_t k = 0; k < cut_bytes_; ++k) {
        const int s = symbol(static_cast<int>(cuts[k]) - static_cast<int>(latest_[k]), bits);
        if (s > 0) {
          const std::size_t bit = k * static_cast<std::size_t>(bits);
          packed[bit / 8] |= static_cast<std::uint8_t>(s << (bit % 8));
        } else if (s < 0) {
          put_u16(exception + n * kExceptionBytes, k);
          exception[n * kExceptionBytes + 2] = cuts[k];
          ++n;
        }
      }
      put_u16(scratch_.data() + 1, n);
    }
  }
  append_record(scratch_);
  std::memcpy(latest_.data(), cuts, cut_bytes_);
}

void CutSnapshots::append_record(const std::vector<std::uint8_t>& record) {
  if (chunks_.empty() || used_in_last_chunk_ + record.size() > kChunkBytes) {
    // Default-initialised: pages committed as records are written.
    chunks_.push_back(std::unique_ptr<std::uint8_t[]>(new std::uint8_t[kChunkBytes]));
    used_in_last_chunk_ = 0;
  }
  std::memcpy(chunks_.back().get() + used_in_last_chunk_, record.data(), record.size());
  offsets_.push_back((chunks_.size() - 1) * kChunkBytes + used_in_last_chunk_);
  used_in_last_chunk_ += record.size();
  record_bytes_ += record.size();
}

const std::uint8_t* CutSnapshots::record(std::size_t index) const {
  const std::uint64_t at = offsets_[index];
  return chunks_[at / kChunkBytes].get() + at % kChunkBytes;
}

void CutSnapshots::apply(std::size_t index, std::uint8_t* cuts) const {
  const std::uint8_t* r = record(index);
  const int bits = r[0];
  const std::size_t n = get_u16(r + 1);
  const std::uint8_t* packed = r + kHeaderBytes;
  if (bits == 8) {
    std::memcpy(cuts, packed, cut_bytes_);
    return;
  }
  if (bits == 2) {
    for (std::size_t k = 0; k < cut_bytes_; ++k) {
      const int s = (packed[k / 4] >> (2 * (k % 4))) & 3;
      cuts[k] = static_cast<std::uint8_t>(cuts[k] + (s == 1) - (s == 2));
    }
  } else if (bits == 4) {
    for (std::size_t k = 0; k < cut_bytes_; ++k) {
      const int s = (packed[k / 2] >> (4 * (k % 2))) & 15;
      if (s != 0) cuts[k] = static_cast<std::uint8_t>(cuts[k] + s - 8);
    }
  }
  const std::uint8_t* exception = packed + (cut_bytes_ * static_cast<std::size_t>(bits) + 7) / 8;
  for (std::size_t e = 0; e < n; ++e)
    cuts[get_u16(exception + e * kExceptionBytes)] = exception[e * kExceptionBytes + 2];
}

const std::uint8_t* CutSnapshots::cuts(std::size_t index) {
  if (index >= offsets_.size()) {
    throw std::out_of_range("CutSnapshots: snapshot " + std::to_string(index) + " of " +
                            std::to_string(offsets_.size()));
  }
  if (index + 1 == offsets_.size()) return latest_.data();
  const std::size_t key = index - index % kKeyEvery;
  std::size_t next = key;
  if (decoded_valid_ && decoded_index_ >= key && decoded_index_ <= index) next = decoded_index_ + 1;
  for (std::size_t i = next; i <= index; ++i) apply(i, decoded_.data());
  decoded_index_ = index;
  decoded_valid_ = true;
  return decoded_.data();
}

std::size_t CutSnapshots::bytes() const {
  return record_bytes_ + offsets_.capacity() * sizeof(std::uint64_t) + latest_.size() + decoded_.size();
}

}  // namespace loopgate
