#!/usr/bin/env bash
# Runs the soak benchmark (src/exocet_mosaic/scripts/soak_dive): renders the hour-long dive once into
# out/bench/cache/ (about 20 minutes on two cores), replays it through the live chain (a few minutes) and writes
# out/bench/soak.json and the soak_* keys of out/bench/reliability.json. Arguments go to soak_dive (--rate, --no-web).
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=tools/workspace-env.sh
source tools/workspace-env.sh
exec devel/lib/exocet_mosaic/soak_dive --output-dir out/bench "$@"
