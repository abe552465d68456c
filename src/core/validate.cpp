#include "core/validate.hpp"

#include <algorithm>

#include "core/error.hpp"

namespace loopgate {

void require_one_of(const std::string& name, const std::string& value,
                    const std::vector<std::string>& allowed) {
  if (std::find(allowed.begin(), allowed.end(), value) == allowed.end()) {
    std::string choices;
    for (std::size_t i = 0; i < allowed.size(); ++i) choices += (i ? "|" : "") + allowed[i];
    throw ConfigError(name + ": '" + value + "' is not one of " + choices);
  }
}

void require(bool ok, const std::string& name, const std::string& message, const std::string& value) {
  if (!ok) throw ConfigError(name + ": must be " + message + " (got " + value + ")");
}

}  // namespace loopgate
