#!/usr/bin/env bash
# Runs every gtest, rostest and whole-system test of the workspace and prints the verdict of catkin_test_results
# (catkin_make run_tests itself exits 0 even when a test fails). Closing line: "N passed, N failed".
#   tools/run-tests.sh               the whole suite (make test)
#   tools/run-tests.sh --gtest-only  the fast tier (make check): every package's gtests, the build checks' tests and
#                                    the Python unit tests (catkin's run_tests_<package>_gtest, _cmake and _python
#                                    targets); no rostest, no master
set -uo pipefail
cd "$(dirname "$0")/.."
mode=all
case "${1:-}" in
  "") ;;
  --gtest-only) mode=gtest ;;
  *) echo "usage: tools/run-tests.sh [--gtest-only]" >&2; exit 2 ;;
esac
export PATH=/usr/bin:/bin:$PATH
export ROS_HOME=${ROS_HOME:-$PWD/out/ros}
mkdir -p out "$ROS_HOME"
set +u  # setup.bash reads unset variables
# shellcheck disable=SC1091
source devel/setup.bash
set -u
rm -rf build/test_results
start=$(date +%s)
if [[ $mode == gtest ]]; then
  log=out/check.log
  # catkin's per-package targets of one test type: run_tests_<package>_gtest, _cmake, _python.
  available=$(make -s -C build help | sed -nE 's/^\.\.\. (run_tests_[A-Za-z0-9_]+)$/\1/p')
  targets=""
  for package in $(sed -nE 's|.*<name>(.*)</name>.*|\1|p' src/*/package.xml | sort -u); do
    for type in gtest cmake python; do
      if grep -qx "run_tests_${package}_${type}" <<< "$available"; then targets="$targets run_tests_${package}_${type}"; fi
    done
  done
  if [[ -z $targets ]]; then
    echo "run-tests: no gtest targets (was the workspace configured with CATKIN_ENABLE_TESTING=ON?)"
    echo "0 passed, 1 failed"
    exit 1
  fi
  echo "Running the test targets:$targets"
  # shellcheck disable=SC2086
  catkin_make $targets -j"$(nproc)" > $log 2>&1
else
  log=out/test.log
  catkin_make run_tests -j"$(nproc)" > $log 2>&1
fi
build_status=$?
grep -E "^\[ RUN|^\[  (FAILED|PASSED)|^\[       OK|FAILURE|ERROR|failed|\[ROSTEST\]|^-- run_tests" $log | grep -v "^\[       OK" | tail -n 80
echo
echo "Full log: $log ($(($(date +%s) - start)) s)"
summary=$(catkin_test_results build/test_results 2>&1)
echo "$summary" | grep -vE "^Skipping" | tail -n 30
# Why each failed test failed (a CI log shows only this output's tail): the failure messages of the result files.
/usr/bin/python3 - build/test_results <<'PY'
import glob, os, sys
import xml.etree.ElementTree as ET
for path in sorted(glob.glob(os.path.join(sys.argv[1], "**", "*.xml"), recursive=True)):
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        print("unreadable result file %s: %s" % (path, e))
        continue
    for case in root.iter("testcase"):
        for bad in list(case.findall("failure")) + list(case.findall("error")):
            text = (bad.get("message") or "") + "\n" + (bad.text or "")
            lines = [l for l in text.strip().splitlines() if l.strip()][:20]
            print("FAILED %s: %s.%s" % (os.path.relpath(path, sys.argv[1]), case.get("classname"), case.get("name")))
            for l in lines:
                print("    " + l[:300])
PY
line=$(echo "$summary" | grep -E "^Summary:" | tail -n 1)
if [[ -z $line ]]; then
  echo "run-tests: no test results were produced (see $log)"
  echo "0 passed, 1 failed"
  exit 1
fi
total=$(echo "$line" | sed -E 's/Summary: ([0-9]+) tests.*/\1/')
errors=$(echo "$line" | sed -E 's/.* ([0-9]+) errors.*/\1/')
failures=$(echo "$line" | sed -E 's/.* ([0-9]+) failures.*/\1/')
skipped=$(echo "$line" | sed -E 's/.* ([0-9]+) skipped.*/\1/')
failed=$((errors + failures))
passed=$((total - failed - skipped))
if [[ $build_status -ne 0 ]]; then
  echo "run-tests: building or running the tests failed (exit $build_status): see $log"
  failed=$((failed + 1))
fi
echo "$passed passed, $failed failed"
[[ $failed -eq 0 ]]
