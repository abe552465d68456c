#!/usr/bin/python3
"""The module dependency rules of loopgate, checked on the #include lines of src/ (stdlib only).

Usage: /usr/bin/python3 scripts/check_includes.py SRC_DIR

SRC_DIR is the source root (src/): it holds core/, bag/, io/, sim/, eval/, stages/, parallel/, pipeline/ and app/,
and
project includes are written relative to it ("stages/gate/pose_gate.hpp"). A quoted include that names a
file next to the including one ("../x.hpp", "x.hpp") is resolved as the compiler would.

Exit status: 0 when every include follows the rules, 1 when one does not (one line per violation:
FILE:LINE: #include ...: the rule), 2 for a bad command line. The rules (docs/architecture.md § Modules):
"""

import os
import re
import sys

MODULES = ("core", "bag", "io", "sim", "eval", "stages", "parallel", "pipeline", "app")
SOURCE_SUFFIXES = (".cpp", ".hpp", ".h", ".cc", ".hh", ".inl", ".ipp")

# (does the rule apply to a file of this module, modules it must not include, the rule as printed);
# the module of a file is its first directory under src/ (None for a file directly in src/).
RULES = (
    (lambda m: m in ("stages", "core"), ("pipeline", "io"),
     "stages/ and core/ must not include pipeline/ or io/"),
    (lambda m: m == "core", ("stages", "io", "pipeline", "sim", "eval", "app", "parallel"),
     "core/ includes only core/"),
    (lambda m: m == "parallel", ("stages", "io", "pipeline", "sim", "eval", "app", "bag"),
     "parallel/ includes only core/ (and TBB)"),
    (lambda m: m not in ("parallel", "pipeline", "sim"), ("parallel",),
     "only pipeline/ and sim/ include parallel/ (TBB's parallel loops)"),
    (lambda m: m == "io", ("stages", "pipeline"), "io/ must not include stages/ or pipeline/"),
    (lambda m: m == "eval", ("pipeline", "stages", "sim", "app"),
     "eval/ must not include pipeline/, stages/, sim/ or app/"),
    (lambda m: m == "sim", ("pipeline", "stages", "app"), "sim/ must not include pipeline/, stages/ or app/"),
    (lambda m: m != "app", ("app",), "only app/ includes app/"),
    (lambda m: m == "bag", ("core", "io", "sim", "eval", "stages", "pipeline", "app"),
     "bag/ includes no other module (it is built as C++17 for the ROS1 headers)"),
    (lambda m: m not in ("io", "bag"), ("bag",), "only io/ includes bag/ (ROS1 bags are read as a Dataset)"),
)
TBB_ALLOWED = ("pipeline", "sim", "parallel")
TBB_RULE = "only pipeline/, sim/ and parallel/ include TBB (a stage is plain code, no threads)"
ROS_ALLOWED = ("bag",)
ROS_RULE = "only bag/ includes ROS1 headers (their generated messages do not compile as C++20)"
ROS_PREFIXES = ("ros/", "rosbag/", "sensor_msgs/", "std_msgs/", "geometry_msgs/")

# The rooms of pipeline/, bottom to top (docs/architecture.md § Rooms of the pipeline). A file in a room
# includes only rooms below or beside it: frame/ (what a frame carries, its input steps, the run clock, the
# gate-feedback channel) < methods/ (detection methods, their registry, distances, stores) < outputs/ (writers,
# summary, run folder, RunResult) < graph/ (the run's objects and node bodies, end-of-run checks). The files
# directly in pipeline/ are the folder's base (pipeline_config, odometry_factory: they include no room) and its
# entry points (pipeline.hpp/.cpp, two_sequence: they may include every room). loop closure (loops/, or the
# loop_* and loops_writer files directly in pipeline/) keeps its own rules.
PIPELINE_ROOMS = ("frame", "methods", "outputs", "graph")
PIPELINE_BASE = ("pipeline_config", "odometry_factory")
PIPELINE_ENTRY = ("pipeline.hpp",)
ROOM_RULE = "pipeline/%s/ must not include pipeline/%s/ (rooms include only rooms below them: %s)"
BASE_RULE = "pipeline/%s must not include pipeline/%s/ (the folder's base includes no room)"
ENTRY_RULE = "only pipeline/pipeline.cpp and app/ include pipeline/pipeline.hpp (the entry point, nothing below it)"

__doc__ += "".join("  - " + rule + "\n" for _, _, rule in RULES) + "  - " + TBB_RULE + "\n"
__doc__ += "  - " + ROS_RULE + "\n"
__doc__ += "  - inside pipeline/: rooms run downhill, " + " < ".join(PIPELINE_ROOMS) + "; the base files ("
__doc__ += ", ".join(PIPELINE_BASE) + ") include no room; " + ENTRY_RULE + "\n"

INCLUDE = re.compile(r'^\s*#\s*include\s*([<"])([^>"]+)[>"]')


def module_of(rel_path):
    """First directory of a path relative to the source root (None for a file at the root)."""
    parts = rel_path.replace(os.sep, "/").split("/")
    return parts[0] if len(parts) > 1 else None


def include_lines(path):
    """(line number, delimiter, included path) of every #include outside /* */ comments."""
    in_comment = False
    with open(path, encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, start=1):
            code = ""
            rest = line
            while rest:
                if in_comment:
                    end = rest.find("*/")
                    if end < 0:
                        rest = ""
                    else:
                        in_comment = False
                        rest = rest[end + 2:]
                else:
                    start = rest.find("/*")
                    if start < 0:
                        code += rest
                        rest = ""
                    else:
                        code += rest[:start]
                        in_comment = True
                        rest = rest[start + 2:]
            match = INCLUDE.match(code)
            if match:
                yield number, match.group(1), match.group(2)


def pipeline_place(rel_path):
    """Where a path relative to the source root sits in pipeline/: ("room", name), ("base", stem),
    ("entry", file name), ("other", ...) for any other pipeline/ file, or None outside pipeline/."""
    parts = rel_path.replace(os.sep, "/").split("/")
    if len(parts) < 2 or parts[0] != "pipeline":
        return None
    if len(parts) > 2:
        return ("room", parts[1]) if parts[1] in PIPELINE_ROOMS else ("other", parts[1])
    stem = os.path.splitext(parts[1])[0]
    if stem in PIPELINE_BASE:
        return ("base", stem)
    if parts[1] in PIPELINE_ENTRY:
        return ("entry", parts[1])
    return ("other", parts[1])


def included_path(src_root, file_path, delimiter, included):
    """The path (relative to the source root) of a project include, or None."""
    if delimiter == '"':
        beside = os.path.normpath(os.path.join(os.path.dirname(file_path), included))
        if included.startswith(".") or os.path.isfile(beside):
            rel = os.path.relpath(beside, src_root)
            return None if rel.startswith("..") else rel.replace(os.sep, "/")
    first = included.replace("\\", "/").split("/")[0]
    return included.replace("\\", "/") if first in MODULES and "/" in included else None


def room_violation(rel_file, rel_included):
    """The room rule an include inside pipeline/ breaks, or None."""
    target = pipeline_place(rel_included)
    if target is None:
        return None
    if target[0] == "entry" and rel_file.replace(os.sep, "/") != "pipeline/pipeline.cpp":
        return ENTRY_RULE if pipeline_place(rel_file) is not None else None
    source = pipeline_place(rel_file)
    if source is None or target[0] != "room":
        return None
    if source[0] == "base":
        return BASE_RULE % (source[1], target[1])
    if source[0] == "room" and PIPELINE_ROOMS.index(target[1]) > PIPELINE_ROOMS.index(source[1]):
        below = PIPELINE_ROOMS[:PIPELINE_ROOMS.index(source[1])]
        return ROOM_RULE % (source[1], target[1], ", ".join(below) if below else "none")
    return None


def included_module(src_root, file_path, delimiter, included):
    """The module an include refers to, or None when it is not a project header."""
    if delimiter == '"':
        beside = os.path.normpath(os.path.join(os.path.dirname(file_path), included))
        if included.startswith(".") or os.path.isfile(beside):
            rel = os.path.relpath(beside, src_root)
            if not rel.startswith(".."):
                return module_of(rel)
    first = included.replace("\\", "/").split("/")[0]
    return first if first in MODULES and "/" in included else None


def is_tbb(included):
    path = included.replace("\\", "/")
    return path.startswith("tbb/") or path.startswith("oneapi/tbb") or path == "tbb.h"


def is_ros(included):
    return included.replace("\\", "/").startswith(ROS_PREFIXES)


def check(src_root):
    """Every violation under src_root as (file, line, include text, rule), in file order."""
    violations = []
    for directory, subdirs, files in os.walk(src_root):
        subdirs.sort()
        for name in sorted(files):
            if not name.endswith(SOURCE_SUFFIXES):
                continue
            path = os.path.join(directory, name)
            module = module_of(os.path.relpath(path, src_root))
            for number, delimiter, included in include_lines(path):
                text = "#include " + (delimiter + included + (">" if delimiter == "<" else '"'))
                if is_tbb(included) and module not in TBB_ALLOWED:
                    violations.append((path, number, text, TBB_RULE))
                if is_ros(included) and module not in ROS_ALLOWED:
                    violations.append((path, number, text, ROS_RULE))
                target = included_module(src_root, path, delimiter, included)
                if target is None:
                    continue
                if module == "pipeline" and target == "pipeline":
                    rel_included = included_path(src_root, path, delimiter, included)
                    rule = room_violation(os.path.relpath(path, src_root), rel_included) if rel_included else None
                    if rule:
                        violations.append((path, number, text, rule))
                    continue
                for applies_to, forbidden, rule in RULES:
                    if applies_to(module) and target in forbidden:
                        violations.append((path, number, text, rule))
                        break  # one line per include: the first rule it breaks
    return violations


def main(argv):
    if len(argv) != 2 or argv[1] in ("-h", "--help"):
        sys.stderr.write("usage: check_includes.py SRC_DIR\n" + __doc__)
        return 2
    src_root = argv[1]
    if not os.path.isdir(src_root):
        sys.stderr.write("check_includes.py: %s is not a directory\n" % src_root)
        return 2
    violations = check(src_root)
    for path, number, text, rule in violations:
        print("%s:%d: %s: %s" % (path, number, text, rule))
    if violations:
        print("include rules: %d violation(s) (rules: scripts/check_includes.py, docs/architecture.md)"
              % len(violations))
        return 1
    print("include rules: every #include under %s follows the module rules" % src_root)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
