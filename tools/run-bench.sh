#!/usr/bin/env bash
# Runs every benchmark (executables named bench_* in the workspace); each prints its figures and writes
# out/bench/<name>.json. Benchmarks measure; they never fail because a machine is slow.
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH=/usr/bin:/bin:$PATH
export ROS_HOME=${ROS_HOME:-$PWD/out/ros}
set +u  # setup.bash reads unset variables
# shellcheck disable=SC1091
source devel/setup.bash
set -u
mkdir -p out/bench
status=0
for bench in devel/lib/*/bench_*; do
  [[ -x $bench ]] || continue
  echo "== $(basename "$bench")"
  if ! "$bench" --output-dir out/bench --shared-data "$PWD/../shared/data"; then
    echo "run-bench: $(basename "$bench") failed" >&2
    status=1
  fi
done
echo "Figures: $(ls out/bench/*.json 2>/dev/null | tr '\n' ' ')"
python3 tools/make-benchmarks-doc.py --bench-dir out/bench --output docs/benchmarks.md || status=1
exit $status
