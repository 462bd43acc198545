#!/usr/bin/env bash
# Renders sample dives of src/exocet_mosaic/config/dives/ into bags/ with the project's simulator: the ones named as arguments
# (e.g. sample_out_and_back), or every src/exocet_mosaic/config/dives/sample_*.yaml.
# A bag is remade only when its description or the simulator changed (the bag is deterministic, so this is safe).
set -euo pipefail
cd "$(dirname "$0")/.."
export PATH=/usr/bin:/bin:$PATH
synth=devel/lib/exocet_mosaic/dive_synth
[[ -x $synth ]] || { echo "make-bags: $synth is missing: run 'make build' first" >&2; exit 1; }
mkdir -p bags
configs=()
if [[ $# -gt 0 ]]; then
  for name in "$@"; do configs+=("src/exocet_mosaic/config/dives/$name.yaml"); done
else
  configs=(src/exocet_mosaic/config/dives/sample_*.yaml)
fi
for config in "${configs[@]}"; do
  [[ -f $config ]] || { echo "make-bags: no dive description $config" >&2; exit 1; }
  name=$(basename "$config" .yaml)
  bag=bags/$name.bag
  # What makes the bag: the description, the simulator library and the sources of the bag writing (dive_synth itself
  # is relinked whenever any node's code changes, which does not change the bag).
  fresh=1
  for input in $config devel/lib/libexocet_mosaic_sim.so devel/lib/libexocet_mosaic_dive.so devel/lib/libexocet_common.so \
      src/exocet_mosaic/src/tools/dive_synth.cpp \
      src/exocet_mosaic/src/ros/dive_bag_writer.cpp src/exocet_mosaic/include/exocet_mosaic/ros/dive_bag_writer.h \
      src/exocet_mosaic/src/ros/synthetic_dive_bag.cpp; do
    [[ $bag -nt $input ]] || fresh=0
  done
  if [[ -f $bag && $fresh == 1 ]]; then
    echo "make-bags: $bag is up to date"
    continue
  fi
  echo "make-bags: rendering $bag from $config"
  "$synth" --config "$config" --output "$bag" --threads "$(nproc)"
done
