#!/usr/bin/env python3
"""Proves that exocet_ros_free_target() stops a build that brings a ROS header into a ROS-free library.

Configures and builds test/ros_include_fixture (a core library checked by the function, a ROS layer beside it) with
no injection (must build), then with `#include <ros/time.h>` injected into a core source, into a public header no
source includes, and into a third-party header a core source includes (each must fail, the output naming the file
and <ros/time.h>). Writes the verdict as a JUnit file for catkin_test_results.
"""
import argparse
import os
import subprocess
import sys
import time
from xml.sax.saxutils import escape, quoteattr

CASES = [
    # name, INJECT, expected to build, strings the build output must contain
    ("clean", "none", True, []),
    ("ros_include_in_core_source", "source", False, ["src/injected.cpp", "ros/time.h", "ROS header"]),
    ("ros_include_in_public_header", "header", False, ["include/fixture/injected.h", "ros/time.h", "ROS header"]),
    ("ros_include_through_third_party_header", "third_party", False,
     ["src/uses_vendor.cpp", "vendor/clock.h", "ros/time.h", "ROS header"]),
]


def run(command):
    result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, universal_newlines=True)
    return result.returncode, result.stdout


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--junit", required=True)
    parser.add_argument("--fixture", required=True)
    parser.add_argument("--module", required=True)
    parser.add_argument("--work-dir", required=True)
    parser.add_argument("--cxx", default="")
    args = parser.parse_args()
    build = os.path.join(args.work_dir, "build")
    results = []
    for name, inject, should_build, expected in CASES:
        start = time.time()
        configure = ["cmake", "-S", args.fixture, "-B", build, "-DEXOCET_ROS_FREE_MODULE=" + args.module,
                     "-DINJECT=" + inject]
        if args.cxx:
            configure.append("-DCMAKE_CXX_COMPILER=" + args.cxx)
        status, output = run(configure)
        failure = None
        if status != 0:
            failure = "configuring the fixture failed (INJECT=%s)" % inject
        else:
            status, output = run(["cmake", "--build", build, "--", "-k"])
            missing = [s for s in expected if s not in output]
            if should_build and status != 0:
                failure = "the fixture without a ROS include did not build"
            elif not should_build and status == 0:
                failure = "the build succeeded although a ROS header was included (INJECT=%s)" % inject
            elif missing:
                failure = "the failed build's output does not name %s" % ", ".join(missing)
        elapsed = time.time() - start
        print("%s: %s (%.1f s)" % (name, "FAILED: " + failure if failure else "ok", elapsed))
        if failure or not should_build:
            print("\n".join("    " + line for line in output.splitlines() if "error" in line or "included from" in line))
        results.append((name, failure, output, elapsed))
    os.makedirs(os.path.dirname(os.path.abspath(args.junit)), exist_ok=True)
    failures = sum(1 for r in results if r[1])
    with open(args.junit, "w") as f:
        f.write('<?xml version="1.0" encoding="utf-8"?>\n')
        f.write('<testsuite name="ros_include_check" tests="%d" failures="%d" errors="0" time="%.1f">\n' %
                (len(results), failures, sum(r[3] for r in results)))
        for name, failure, output, elapsed in results:
            f.write('  <testcase classname="exocet_cmake.RosIncludeCheck" name="%s" time="%.1f">\n' % (name, elapsed))
            if failure:
                f.write("    <failure message=%s>%s</failure>\n" % (quoteattr(failure), escape(output[-4000:])))
            f.write("    <system-out>%s</system-out>\n" % escape(output[-4000:]))
            f.write("  </testcase>\n")
        f.write("</testsuite>\n")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
