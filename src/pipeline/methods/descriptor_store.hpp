// The DIRD descriptors of one run, by sequence number (full and gated mode): written once per frame by the
// describe node (in parallel) and read by the similarity rows of later frames. Frame index and time of a
// sequence number are the run's (PipelineRun keeps them), not the store's.
//
// Publication: publish() stores the state with release after the descriptor was written;
// readers check state() with acquire before they read an entry (this is also the hand-over that
// ThreadSanitizer sees). Capacity is fixed at construction (the number of frames the run may release);
// the descriptor array is allocated uninitialised, so memory is committed only as frames are written:
// 3456 bytes of descriptor + 1 state byte per frame.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/types.hpp"
#include "stages/dird/dird_extractor.hpp"

namespace loopgate {

class DescriptorStore {
 public:
  enum class State : std::uint8_t { kEmpty = 0, kNoDescriptor = 1, kValid = 2 };

  explicit DescriptorStore(std::size_t capacity)
      : capacity_(capacity),
        descriptors_(new Descriptor[capacity]),
        state_(new std::atomic<std::uint8_t>[capacity]) {
    for (std::size_t k = 0; k < capacity; ++k) state_[k].store(0, std::memory_order_relaxed);
  }

  std::size_t capacity() const { return capacity_; }

  // Slot for the describe node of `seq` to extract into, before publish().
  Descriptor& slot(std::size_t seq) { return descriptors_[check(seq)]; }

  // Publishes entry `seq`: `valid` = the slot holds the frame's descriptor; otherwise the slot is zeroed
  // (no descriptor, e.g. the image did not decode) and rows skip it.
  void publish(std::size_t seq, bool valid) {
    check(seq);
    if (!valid) std::memset(descriptors_[seq].data(), 0, kDirdBytes);
    state_[seq].store(static_cast<std::uint8_t>(valid ? State::kValid : State::kNoDescriptor),
                      std::memory_order_release);
  }

  State state(std::size_t seq) const {
    return static_cast<State>(state_[check(seq)].load(std::memory_order_acquire));
  }
  const Descriptor* data() const { return descriptors_.get(); }
  const Descriptor& descriptor(std::size_t seq) const { return descriptors_[check(seq)]; }

 private:
  std::size_t check(std::size_t seq) const {
    if (seq >= capacity_) {
      throw std::out_of_range("DescriptorStore: seq " + std::to_string(seq) + " beyond capacity " +
                              std::to_string(capacity_));
    }
    return seq;
  }

  std::size_t capacity_;
  std::unique_ptr<Descriptor[]> descriptors_;  // default-initialised: pages committed when written
  std::unique_ptr<std::atomic<std::uint8_t>[]> state_;
};

}  // namespace loopgate
