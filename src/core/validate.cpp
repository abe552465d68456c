#include "core/validate.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>

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

namespace {
std::string shortest(double value) {
  char buffer[64];
  const auto [ptr, ec] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return ec == std::errc{} ? std::string(buffer, ptr) : std::string("nan");
}
}  // namespace

void require_in(const std::string& name, double value, double lo, double hi, const std::string& unit) {
  if (!(value >= lo && value <= hi)) {
    require(false, name, "in [" + shortest(lo) + ", " + shortest(hi) + "]" + (unit.empty() ? "" : " " + unit),
            shortest(value));
  }
}

void require(bool ok, const std::string& name, const std::string& message, const std::string& value) {
  if (!ok) throw ConfigError(name + ": must be " + message + " (got " + value + ")");
}

}  // namespace loopgate
