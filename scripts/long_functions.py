#!/usr/bin/python3
"""Lists the functions of C++ sources longer than a limit, longest first (stdlib only).

Usage: /usr/bin/python3 scripts/long_functions.py [--limit N] PATH...

A function is a brace block at namespace or class level whose opening line holds a ')' before the '{' (a
definition, a lambda assigned at namespace level, a constructor with an initialiser list); its length counts the
lines from its signature's first line to its closing brace. Strings, characters and comments are skipped when
matching braces. Prints "LINES FILE:LINE NAME" per function above the limit (default 120); exit 0.
"""

import os
import re
import sys

SUFFIXES = (".cpp", ".hpp", ".cc", ".h")


def digit_separator(text, i):
    """Whether the quote at i separates digits of a number (1'000'000), not a character literal."""
    j = i
    while j > 0 and (text[j - 1].isalnum() or text[j - 1] in "_'"):
        j -= 1
    return j < i and text[j].isdigit()


def strip_code(text):
    """The text with comments, strings and character literals blanked (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = text.find(")" + m.group(1) + '"', i) if m else -1
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == "'" and digit_separator(text, i):
            out.append(c)
            i += 1
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(" " * (min(j + 1, n) - i))
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    """(first line, last line, name) of every function body in the file."""
    with open(path, encoding="utf-8", errors="replace") as f:
        code = strip_code(f.read())
    found = []
    stack = []  # (kind, start offset of the statement, name)
    statement_start = 0
    for i, c in enumerate(code):
        if c == "{":
            head = code[statement_start:i]
            in_function = any(kind == "function" for kind, _, _ in stack)
            kind = "block"
            name = ""
            if not in_function and ")" in head and not re.search(r"\b(namespace|class|struct|enum|union)\b[^()]*$", head):
                kind = "function"
                m = re.search(r"([~\w:<>]+)\s*\(", head)
                name = m.group(1) if m else "?"
                # the statement's first non-blank character
                lead = len(head) - len(head.lstrip())
                start = statement_start + lead
            else:
                start = i
            stack.append((kind, start, name))
            statement_start = i + 1
        elif c == "}":
            if stack:
                kind, start, name = stack.pop()
                if kind == "function":
                    found.append((code.count("\n", 0, start) + 1, code.count("\n", 0, i) + 1, name))
            statement_start = i + 1
        elif c == ";":
            statement_start = i + 1
        elif c == ":" and not stack_is_function(stack) and re.search(r"\b(public|private|protected)\s*$", code[statement_start:i]):
            statement_start = i + 1
        elif c == "\n" and code[statement_start:i].lstrip().startswith("#"):
            statement_start = i + 1
    return found


def stack_is_function(stack):
    return any(kind == "function" for kind, _, _ in stack)


def main(argv):
    limit = 120
    paths = []
    args = argv[1:]
    while args:
        a = args.pop(0)
        if a == "--limit":
            limit = int(args.pop(0))
        else:
            paths.append(a)
    if not paths:
        sys.stderr.write(__doc__)
        return 2
    rows = []
    for top in paths:
        files = [top] if os.path.isfile(top) else [os.path.join(d, f) for d, _, fs in os.walk(top) for f in fs]
        for path in sorted(files):
            if path.endswith(SUFFIXES):
                for first, last, name in functions(path):
                    if last - first + 1 > limit:
                        rows.append((last - first + 1, path, first, name))
    for lines, path, first, name in sorted(rows, reverse=True):
        print("%4d %s:%d %s" % (lines, path, first, name))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
