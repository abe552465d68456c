// Helpers for the validate() of configuration sections (see io/config.hpp): each throws ConfigError whose
// message starts with the key ("section.key: ..."). In core so that a stage validates its own section
// without depending on the configuration system of src/io.
#pragma once

#include <string>
#include <vector>

namespace loopgate {

// Throws ConfigError "NAME: 'VALUE' is not one of a|b|c" unless value is allowed.
void require_one_of(const std::string& name, const std::string& value,
                    const std::vector<std::string>& allowed);
// Throws ConfigError "NAME: must be MESSAGE (got VALUE)" when !ok.
void require(bool ok, const std::string& name, const std::string& message, const std::string& value);

}  // namespace loopgate
