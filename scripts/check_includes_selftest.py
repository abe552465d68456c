#!/usr/bin/python3
"""Proves that scripts/check_includes.py catches what it should (stdlib only).

Usage: /usr/bin/python3 scripts/check_includes_selftest.py

Builds scratch source trees in a temporary directory, one violating file each, runs the checker on them
and expects exit 1 with "FILE:LINE: #include ...: rule" naming the file, the line and the include; a tree
that follows the rules must give exit 0. Prints the checker's output for the first case (a stage including
pipeline/). Exit 0 when every case behaves, 1 otherwise.
"""

import os
import subprocess
import sys
import tempfile

CHECKER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "check_includes.py")

# (file under src/, its text, line of the violating include or None when the tree must pass)
CASES = (
    ("stages/x/bad.cpp", '#include "stages/x/bad.hpp"\n\n#include "pipeline/pipeline.hpp"\n', 3),
    ("stages/x/io_user.cpp", '// reads files\n#include "io/dataset.hpp"\n', 2),
    ("stages/x/threads.cpp", "#include <vector>\n#include <tbb/parallel_for.h>\n", 2),
    ("stages/x/one_tbb.hpp", "#include <oneapi/tbb/flow_graph.h>\n", 1),
    ("core/up.hpp", '#include "core/types.hpp"\n#include "eval/ground_truth.hpp"\n', 2),
    ("core/relative.cpp", '#include "../io/config.hpp"\n', 1),
    ("io/reader.cpp", '#include "io/dataset.hpp"\n#include "stages/dird/dird_config.hpp"\n', 2),
    ("eval/metric.cpp", '#include "sim/world.hpp"\n', 1),
    ("sim/driver.cpp", '#include "pipeline/pipeline.hpp"\n', 1),
    ("pipeline/run.cpp", '#include "app/commands.hpp"\n', 1),
    ("loose.cpp", '#include <vector>\n#include "app/commands.hpp"\n', 2),
    ("eval/tbb_user.cpp", "#include <tbb/parallel_for.h>\n", 1),
    ("io/ros_user.cpp", '#include "io/dataset.hpp"\n#include <sensor_msgs/Image.h>\n', 2),
    ("pipeline/bag_user.cpp", '#include "bag/bag_reader.hpp"\n', 1),
    ("bag/up.cpp", '#include <rosbag/bag.h>\n#include "core/types.hpp"\n', 2),
    # The rooms of pipeline/: a method including the graph or the outputs, outputs including the graph, the
    # frame room including a method, the base including a room, a room including the entry point upwards.
    ("pipeline/methods/m.cpp", '#include "pipeline/frame/frame_record.hpp"\n#include "pipeline/graph/g.hpp"\n', 2),
    ("pipeline/methods/w.cpp", '#include "pipeline/outputs/run_outputs.hpp"\n', 1),
    ("pipeline/outputs/o.cpp", '#include "pipeline/methods/m.hpp"\n#include "../graph/pipeline_run.hpp"\n', 2),
    ("pipeline/frame/f.hpp", '#include "pipeline/methods/detection_method.hpp"\n', 1),
    ("pipeline/pipeline_config.cpp", '#include "pipeline/methods/method_registry.hpp"\n', 1),
    ("pipeline/outputs/r.cpp", '#include "pipeline/pipeline.hpp"\n', 1),
    ("pipeline/loop_x.cpp", '#include "pipeline/pipeline_config.hpp"\n#include "pipeline/pipeline.hpp"\n', 2),
    # Allowed: the rooms downhill, the entry point over every room, app/ over the entry point.
    ("pipeline/graph/g.cpp", '#include "pipeline/outputs/o.hpp"\n#include "pipeline/methods/m.hpp"\n'
     '#include "pipeline/frame/f.hpp"\n#include "pipeline/pipeline_config.hpp"\n', None),
    ("pipeline/outputs/o.cpp", '#include "pipeline/methods/m.hpp"\n#include "pipeline/frame/f.hpp"\n', None),
    ("pipeline/pipeline.cpp", '#include "pipeline/pipeline.hpp"\n#include "pipeline/graph/g.hpp"\n', None),
    # Allowed: the layering as it is meant to be, TBB in pipeline/ and sim/, includes in comments.
    ("pipeline/graph.cpp",
     '#include <tbb/flow_graph.h>\n#include "io/dataset.hpp"\n#include "stages/gate/pose_gate.hpp"\n', None),
    ("sim/render.cpp", '#include <tbb/parallel_for.h>\n#include "io/writers.hpp"\n', None),
    ("stages/gate/gate.cpp", '#include "core/types.hpp"\n// #include "pipeline/pipeline.hpp"\n'
     '/* #include "io/dataset.hpp" */\n#include "stages/dird/dird_config.hpp"\n', None),
    ("app/main.cpp", '#include "app/commands.hpp"\n#include "pipeline/pipeline.hpp"\n', None),
    ("bag/reader.cpp", '#include "bag/reader.hpp"\n#include <rosbag/bag.h>\n#include <sensor_msgs/Imu.h>\n', None),
    ("io/bag_dataset.cpp", '#include "bag/bag_reader.hpp"\n#include "io/dataset.hpp"\n', None),
)


def run_case(scratch, rel_path, text, line):
    src = os.path.join(scratch, "src")
    path = os.path.join(src, rel_path)
    os.makedirs(os.path.dirname(path))
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    result = subprocess.run([sys.executable, CHECKER, src], capture_output=True, text=True, check=False)
    output = result.stdout + result.stderr
    problems = []
    if line is None:
        if result.returncode != 0:
            problems.append("expected exit 0, got %d" % result.returncode)
    else:
        if result.returncode != 1:
            problems.append("expected exit 1, got %d" % result.returncode)
        where = "%s:%d: %s: " % (path, line, text.splitlines()[line - 1].strip())
        if where not in output:
            problems.append("expected the message to name '%s'" % where)
    return output, problems


def main():
    failures = 0
    for index, (rel_path, text, line) in enumerate(CASES):
        with tempfile.TemporaryDirectory(prefix="check-includes-") as scratch:
            output, problems = run_case(scratch, rel_path, text, line)
        if index == 0:
            print("checker output on a scratch tree with src/%s:" % rel_path)
            print(output.rstrip())
            print()
        status = "ok  " if not problems else "FAIL"
        expected = "passes" if line is None else "fails at line %d" % line
        print("%s src/%s %s" % (status, rel_path, expected))
        for problem in problems:
            failures += 1
            print("     %s; checker output:\n%s" % (problem, output.rstrip()))
    print("check_includes self-test: %s" % ("passed" if failures == 0 else "%d problem(s)" % failures))
    return 0 if failures == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
