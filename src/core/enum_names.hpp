// Names of the values of an enum class, for configuration fields that take one of a few words (run.mode,
// run.method, ...): the config system parses the word into the enum once, prints it back and echoes it in
// JSON. Declare, next to the enum, a function found by argument-dependent lookup:
//   constexpr std::span<const EnumName<RunMode>> enum_names(RunMode) { return kRunModeNames; }
#pragma once

#include <span>
#include <string>
#include <string_view>

namespace loopgate {

template <class E>
struct EnumName {
  E value;
  std::string_view name;
};

// The name of `value` ("?" when the table lacks it).
template <class E>
std::string_view enum_name(E value) {
  for (const EnumName<E>& n : enum_names(value))
    if (n.value == value) return n.name;
  return "?";
}

// "a|b|c": the accepted words, for messages.
template <class E>
std::string enum_choices(E any) {
  std::string out;
  for (const EnumName<E>& n : enum_names(any)) out += (out.empty() ? "" : "|") + std::string(n.name);
  return out;
}

}  // namespace loopgate
