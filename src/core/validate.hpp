// Helpers for the validate() of configuration sections (see io/config.hpp): each throws ConfigError whose
// message starts with the key ("section.key: ..."). In core so that a stage validates its own section
// without depending on the configuration system of src/io.
#pragma once

#include <string>
#include <type_traits>
#include <vector>

namespace loopgate {

// Throws ConfigError "NAME: 'VALUE' is not one of a|b|c" unless value is allowed.
void require_one_of(const std::string& name, const std::string& value,
                    const std::vector<std::string>& allowed);
// Throws ConfigError "NAME: must be MESSAGE (got VALUE)" when !ok.
void require(bool ok, const std::string& name, const std::string& message, const std::string& value);

// Throws ConfigError "NAME: must be in [LO, HI] UNIT (got VALUE)" unless lo <= value <= hi (NaN is out):
// every parameter is bounded by what makes sense, so that no value can make a run hang or exhaust memory.
void require_in(const std::string& name, double value, double lo, double hi, const std::string& unit = "");
template <class T>
requires std::is_integral_v<T>
void require_in(const std::string& name, T value, std::type_identity_t<T> lo, std::type_identity_t<T> hi,
                const std::string& unit = "") {
  if (value < lo || value > hi) {
    require(false, name,
            "in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]" + (unit.empty() ? "" : " " + unit),
            std::to_string(value));
  }
}

}  // namespace loopgate
