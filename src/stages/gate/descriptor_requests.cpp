#include "stages/gate/descriptor_requests.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace loopgate {

bool DescriptorRequests::request(std::int64_t frame) {
  if (frame < 0) throw std::out_of_range("DescriptorRequests: negative frame " + std::to_string(frame));
  const auto index = static_cast<std::size_t>(frame);
  if (index >= bits_.size()) bits_.resize(std::max(index + 1, 2 * bits_.size()), false);
  if (bits_[index]) return false;
  bits_[index] = true;
  ++count_;
  return true;
}

bool DescriptorRequests::requested(std::int64_t frame) const {
  if (frame < 0) return false;
  const auto index = static_cast<std::size_t>(frame);
  return index < bits_.size() && bits_[index];
}

}  // namespace loopgate
