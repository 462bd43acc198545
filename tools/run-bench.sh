#!/usr/bin/env bash
# Runs every benchmark (executables named bench_* in the workspace); each prints its figures and writes
# out/bench/<name>.json. Benchmarks measure; they never fail because a machine is slow.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=tools/workspace-env.sh
source tools/workspace-env.sh
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
