#!/usr/bin/python3
"""Closed word choices of the configuration are enums, not strings (stdlib only).

Usage: /usr/bin/python3 scripts/check_config_choices.py SRC_DIR

A configuration field is a member that a section's fields() visits (`v("key", self.NAME)`). When such a
field is declared `std::string` and the code compares it to a string literal (`x.NAME == "word"`,
`"word" != NAME`) or checks it against a list of words (`require_one_of("...", NAME, {...})`), the field is
a closed choice kept as text: it should be an enum class with a name table (core/enum_names.hpp), which the
config loader parses once (an error naming file:line and the allowed words) and prints back.

Exit status: 0 when no such comparison is found outside ALLOWED, 1 otherwise (one line per finding:
FILE:LINE: the field and the comparison; also when an ALLOWED name is no text field any more, so that the
list only shrinks), 2 for a bad command line.
"""

import os
import re
import sys

SOURCE_SUFFIXES = (".cpp", ".hpp")

# Fields that may stay text, with the reason: a word-or-number value is not a closed choice. The list only
# shrinks.
ALLOWED = {
    "rate": "run.rate is 'max' or a number (an open value, parsed by RunConfig::rate_factor)",
}

FIELD_VISIT = re.compile(r'\bv\(\s*"[^"]+"\s*,\s*self\.(\w+)\s*\)')
STRING_DECL = re.compile(r"^\s*std::string\s+(\w+)\s*(?:=|;|\{)")
STRUCT = re.compile(r"\bstruct\s+\w+\s*(?:final\s*)?(?::[^{;]*)?\{")
COMMENT = re.compile(r"//.*$")
LITERAL = r'"(?:[^"\\]|\\.)*"'


def source_files(root):
    for directory, _, names in sorted(os.walk(root)):
        for name in sorted(names):
            if name.endswith(SOURCE_SUFFIXES):
                yield os.path.join(directory, name)


def struct_bodies(text):
    """The text of every `struct NAME {...}` (braces matched; nested structs are inside their parent's)."""
    for m in STRUCT.finditer(text):
        depth = 0
        for end in range(m.end() - 1, len(text)):
            depth += {"{": 1, "}": -1}.get(text[end], 0)
            if depth == 0:
                yield text[m.end():end]
                break


def string_fields(files):
    """Names of std::string members that their own struct's fields() visits."""
    fields = set()
    for path in files:
        if not path.endswith(".hpp"):
            continue
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        for body in struct_bodies(text):
            visited = set(FIELD_VISIT.findall(body))
            declared = {m.group(1) for line in body.splitlines() for m in [STRING_DECL.match(line)] if m}
            fields |= visited & declared
    return fields


def findings(root):
    files = list(source_files(root))
    text_fields = string_fields(files)
    # An allowance for a field that is no text field any more is stale: the list only shrinks.
    out = ["%s: ALLOWED names '%s', which is no std::string config field any more: remove it" %
           (os.path.basename(__file__), name) for name in sorted(set(ALLOWED) - text_fields)]
    fields = sorted(text_fields - set(ALLOWED))
    if not fields:
        return out
    names = "|".join(fields)
    # A member access (x.NAME, x->NAME) or, in the file of its own struct's methods, the bare NAME.
    member = r"(?:\b\w+(?:\.|->))+(?:%s)\b" % names
    bare = r"(?<![\w.>])(?:%s)\b" % names
    for path in files:
        rel = os.path.relpath(path, root)
        with open(path, encoding="utf-8", errors="replace") as f:
            lines = f.read().splitlines()
        for number, line in enumerate(lines, start=1):
            code = COMMENT.sub("", line)
            for operand in (member, bare):
                compare = re.compile(r"(%s)\s*[!=]=\s*%s|%s\s*[!=]=\s*(%s)" % (operand, LITERAL, LITERAL, operand))
                listed = re.compile(r"require_one_of\(\s*%s\s*,\s*(%s)\s*," % (LITERAL, operand))
                m = compare.search(code) or listed.search(code)
                if m:
                    what = next(g for g in m.groups() if g)
                    out.append("%s:%d: config field '%s' compared to a word: make it an enum with enum_names "
                               "(core/enum_names.hpp)" % (rel, number, what.split(".")[-1].split(">")[-1]))
                    break
    return out


def main(argv):
    if len(argv) != 2 or not os.path.isdir(argv[1]):
        sys.stderr.write(__doc__)
        return 2
    problems = findings(argv[1])
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
