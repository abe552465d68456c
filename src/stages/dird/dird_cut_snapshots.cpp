#include "stages/dird/dird_cut_snapshots.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <stdexcept>
#include <string>

namespace loopgate {

namespace {

constexpr std::size_t kChunkBytes = std::size_t{1} << 20;
constexpr std::size_t kHeaderBytes = 3;     // packed width in bits, then the exception count (uint16)
constexpr std::size_t kExceptionBytes = 3;  // index (uint16), new value
constexpr std::size_t kReadPadding = 8;     // readable bytes after the last record of a chunk

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

// Rice code of the change d of one byte: u = zigzag(d) (0, -1, 1, -2, ... -> 0, 1, 2, 3, ...), then
// q = u >> k as q one bits and a zero bit, then the k low bits of u. A byte with q >= kUnaryCap is kUnaryCap
// one bits and an exception. Records of modes kRiceMode + k, k = 0..3.
constexpr int kRiceMode = 16;
constexpr unsigned kUnaryCap = 12;

unsigned zigzag(int d) {
  return d >= 0 ? 2U * static_cast<unsigned>(d) : 2U * static_cast<unsigned>(-d) - 1U;
}

int unzigzag(unsigned u) {
  return (u & 1U) ? -static_cast<int>((u + 1) / 2) : static_cast<int>(u / 2);
}

// Bits of the Rice code of change d at parameter k; kUnaryCap when it is an exception.
std::size_t rice_bits(int d, int k) {
  const unsigned q = zigzag(d) >> k;
  return q >= kUnaryCap ? kUnaryCap : q + 1 + static_cast<unsigned>(k);
}

struct BitWriter {
  std::uint8_t* p;
  std::size_t bit = 0;
  void put(unsigned b) {
    if (b) p[bit / 8] |= static_cast<std::uint8_t>(1U << (bit % 8));
    ++bit;
  }
};

// Writes the Rice codes of the changes `after - before` at parameter k into `stream` (zeroed, large enough)
// and the exceptions into `exception`; returns their count.
std::size_t write_rice(const std::uint8_t* before, const std::uint8_t* after, std::size_t n, int k,
                       std::uint8_t* stream, std::vector<std::uint8_t>& exception) {
  BitWriter w{stream};
  std::size_t exceptions = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned u = zigzag(static_cast<int>(after[i]) - static_cast<int>(before[i]));
    const unsigned q = u >> k;
    if (q >= kUnaryCap) {
      for (unsigned b = 0; b < kUnaryCap; ++b) w.put(1);
      exception.resize(exception.size() + kExceptionBytes);
      put_u16(exception.data() + exception.size() - kExceptionBytes, i);
      exception.back() = after[i];
      ++exceptions;
      continue;
    }
    for (unsigned b = 0; b < q; ++b) w.put(1);
    w.put(0);
    for (int b = 0; b < k; ++b) w.put((u >> b) & 1U);
  }
  return exceptions;
}

// Applies the Rice codes at `stream` to `cuts` (exceptions left as they are); returns the stream's bytes.
// Reads 8 bytes at a time (a record is followed by at least kReadPadding readable bytes): a code is at most
// kUnaryCap + 1 + 3 = 16 bits, within the 56 bits left after the byte's bit offset.
std::size_t read_rice(const std::uint8_t* stream, std::size_t n, int k, std::uint8_t* cuts) {
  std::size_t bit = 0;
  const std::uint64_t low_mask = (std::uint64_t{1} << k) - 1;
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t window;
    std::memcpy(&window, stream + bit / 8, sizeof window);  // little-endian: bit b of the stream first
    window >>= bit % 8;
    const auto q = static_cast<unsigned>(std::countr_one(window));
    if (q >= kUnaryCap) {
      bit += kUnaryCap;
      continue;
    }
    const auto u =
        static_cast<unsigned>((static_cast<std::uint64_t>(q) << k) | ((window >> (q + 1)) & low_mask));
    cuts[i] = static_cast<std::uint8_t>(cuts[i] + unzigzag(u));
    bit += q + 1 + static_cast<std::size_t>(k);
  }
  return (bit + 7) / 8;
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
    std::size_t exceptions[3] = {0, 0, 0};                                  // 0, 2, 4 bits
    std::size_t rice[4] = {0, 0, 0, 0}, rice_exceptions[4] = {0, 0, 0, 0};  // bits, k = 0..3
    for (std::size_t k = 0; k < cut_bytes_; ++k) {
      const int d = static_cast<int>(cuts[k]) - static_cast<int>(latest_[k]);
      for (int w = 0; w < 3; ++w) exceptions[w] += symbol(d, 2 * w) < 0 ? 1 : 0;
      for (int r = 0; r < 4; ++r) {
        rice[r] += rice_bits(d, r);
        rice_exceptions[r] += (zigzag(d) >> r) >= kUnaryCap ? 1 : 0;
      }
    }
    int bits = 8;
    std::size_t best = cut_bytes_;
    for (int w = 0; w < 3; ++w) {
      const std::size_t size = (cut_bytes_ * 2 * w + 7) / 8 + exceptions[w] * kExceptionBytes;
      if (size < best && exceptions[w] <= 0xffff) best = size, bits = 2 * w;
    }
    for (int r = 0; r < 4; ++r) {
      const std::size_t size = (rice[r] + 7) / 8 + rice_exceptions[r] * kExceptionBytes;
      if (size < best && rice_exceptions[r] <= 0xffff) best = size, bits = kRiceMode + r;
    }
    if (bits >= kRiceMode) {
      scratch_.assign(kHeaderBytes + best, 0);
      scratch_[0] = static_cast<std::uint8_t>(bits);
      std::vector<std::uint8_t> exception;
      const std::size_t n = write_rice(latest_.data(), cuts, cut_bytes_, bits - kRiceMode,
                                       scratch_.data() + kHeaderBytes, exception);
      put_u16(scratch_.data() + 1, n);
      // std::copy, not memcpy: a record without exceptions has an empty vector, whose data() may be null.
      std::copy(exception.begin(), exception.end(),
                scratch_.end() - static_cast<std::ptrdiff_t>(exception.size()));
      append_record(scratch_);
      std::memcpy(latest_.data(), cuts, cut_bytes_);
      return;
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
    // Zeroed: the Rice reader may look up to kReadPadding bytes past a record.
    chunks_.push_back(std::unique_ptr<std::uint8_t[]>(new std::uint8_t[kChunkBytes + kReadPadding]()));
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
  std::size_t packed_bytes = (cut_bytes_ * static_cast<std::size_t>(bits) + 7) / 8;
  if (bits >= kRiceMode) {
    packed_bytes = read_rice(packed, cut_bytes_, bits - kRiceMode, cuts);
  } else if (bits == 2) {
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
  const std::uint8_t* exception = packed + packed_bytes;
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
