// The set of frames whose descriptor has been requested (docs/gating.md § Lazy description: a descriptor is
// computed at most once, only for frames some candidate area needs). A growable bitmap indexed by frame.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace loopgate {

class DescriptorRequests {
 public:
  // Marks `frame` (>= 0) as requested. Returns true the first time, false afterwards.
  bool request(std::int64_t frame);
  bool requested(std::int64_t frame) const;
  std::size_t count() const { return count_; }

 private:
  std::vector<bool> bits_;
  std::size_t count_ = 0;
};

}  // namespace loopgate
