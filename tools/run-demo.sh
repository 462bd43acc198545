#!/usr/bin/env bash
# The demo (make demo): replays the sample dive bag on sim time through the Exocet nodes (exocet_mosaic's launch/demo.launch), then
# plots its trajectories. Everything goes under out/demo/; the script ends by itself and lists what it wrote.
#
# Environment (all optional):
#   EXOCET_DEMO_BAG         bag to replay (default bags/sample_lawnmower.bag)
#   EXOCET_DEMO_RATE        replay speed, times real time (default 3)
#   EXOCET_DEMO_OUT         output folder (default out/demo; emptied first)
#   EXOCET_DEVEL            catkin devel space to use (default devel, as made by `make build`)
#   EXOCET_DEMO_MASTER_URI  join this ROS master (e.g. one your rviz uses) instead of starting a private one
set -euo pipefail
# Debian's ROS wants /usr/bin/python3: a pyenv python3 earlier in PATH breaks roslaunch and rosbag.
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

bag=${EXOCET_DEMO_BAG:-bags/sample_lawnmower.bag}
rate=${EXOCET_DEMO_RATE:-3}
out=${EXOCET_DEMO_OUT:-$root/out/demo}
devel=${EXOCET_DEVEL:-$root/devel}
[[ $bag == /* ]] || bag=$root/$bag  # roslaunch runs the nodes in ROS_HOME: relative paths would not resolve
[[ $out == /* ]] || out=$root/$out
export ROS_HOME=${ROS_HOME:-$root/out/ros}

if [[ ! -f $bag ]]; then
  echo "run-demo: no bag $bag: make it with 'make bags' (tools/make-bags.sh renders the sample dives)" >&2
  exit 1
fi
if [[ ! -f $devel/setup.bash ]]; then
  echo "run-demo: no $devel/setup.bash: build the workspace first with 'make build'" >&2
  exit 1
fi
set +u  # setup.bash reads unset variables
# shellcheck disable=SC1091
source "$devel/setup.bash"
set -u

# A private master on a free port: a roscore someone else runs on this machine (port 11311) must not see our sim
# clock, nor we its topics.
if [[ -n ${EXOCET_DEMO_MASTER_URI:-} ]]; then
  export ROS_MASTER_URI=$EXOCET_DEMO_MASTER_URI
  port_args=()
else
  port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  export ROS_MASTER_URI=http://127.0.0.1:$port
  port_args=(-p "$port")
fi

duration_s=$(rosbag info --yaml --key=duration "$bag") || {
  echo "run-demo: cannot read $bag (rosbag info failed): remake it with 'make bags'" >&2
  exit 1
}
# Generous: replay time, twice over, plus start-up and shutdown. roslaunch ends on its own when the bag ends
# (its replay_watcher is required); the timeout only guards against a node that hangs.
limit_s=$(python3 -c "import math; print(int(math.ceil(2.0 * $duration_s / $rate)) + 120)")

rm -rf "$out"
mkdir -p "$out" "$ROS_HOME"
log=$out/replay.log
printf 'run-demo: replaying %s (%.0f s of dive at %sx real time, about %.0f s)\n' "$bag" "$duration_s" "$rate" \
  "$(python3 -c "print($duration_s / $rate)")"
status=0
timeout --signal=INT --kill-after=30 "$limit_s" \
  roslaunch "${port_args[@]}" src/exocet_mosaic/launch/demo.launch bag:="$bag" output_dir:="$out" rate:="$rate" > "$log" 2>&1 ||
  status=$?
if [[ $status -ne 0 ]]; then
  [[ $status -eq 124 ]] && echo "run-demo: the replay did not end within $limit_s s and was stopped" >&2
  echo "run-demo: roslaunch failed (exit $status); the end of $log:" >&2
  tail -n 30 "$log" >&2
  exit 1
fi
# The replay_watcher ending cleanly is the normal end (the tile writer has written its last tile); its failure (the
# player failed or never started: a node did not come up) ends the launch early, and roslaunch still exits 0: say so
# rather than plot a part.
if grep -A1 -E "REQUIRED process \[" "$log" | grep -v -E "REQUIRED process \[replay_watcher-|finished cleanly|^--" |
  grep -q .; then
  echo "run-demo: a node failed before the end of the bag; from $log:" >&2
  grep -E "FATAL|ERROR|REQUIRED process" "$log" | head -n 20 >&2
  exit 1
fi

echo "run-demo: plotting the trajectories"
# dive_synth writes the true camera centres beside the bag: the reference of the fused (camera) tracks.
camera_truth=()
[[ -f ${bag%.bag}.ground_truth.csv ]] && camera_truth=(--camera-truth "${bag%.bag}.ground_truth.csv")
rosrun exocet_mosaic plot_trajectories --input "$out" --output "$out/trajectories.png" \
  --dive-name "$(basename "$bag" .bag)" "${camera_truth[@]}"

echo "run-demo: tiles overview and gdalinfo summaries"
tiles=("$out"/tiles/tile_*.tif)
if [[ ! -e ${tiles[0]} ]]; then
  echo "run-demo: no tile was written in $out/tiles; from $log:" >&2
  grep -E "tile writer" "$log" | tail -n 20 >&2
  exit 1
fi
rosrun exocet_mosaic tiles_overview --tiles "$out/tiles" --track "$out/fused_track.csv" \
  --output "$out/tiles_overview.png"

echo "run-demo: after the dive, the overlapping tiles adjusted into agreement (adjust_tiles)"
rm -rf "$out/tiles_adjusted"
mkdir -p "$out/tiles_adjusted"
rosrun exocet_mosaic adjust_tiles --tiles "$out/tiles" --output "$out/tiles_adjusted" \
  --report "$out/tiles_adjusted/adjustment.json"
rosrun exocet_mosaic tiles_overview --tiles "$out/tiles_adjusted" --track "$out/fused_track.csv" \
  --output "$out/tiles_adjusted_overview.png"
echo "run-demo: the web map of the dive (a static site: open it from disk or serve the folder)"
rosrun exocet_web web_map_site --tiles "$out/tiles" --site "$out/web" --track "$out/fused_track.csv" \
  --dive-name "$(basename "$bag" .bag)" \
  > "$out/web_map_site.log" 2>&1 || { echo "run-demo: web_map_site failed; $out/web_map_site.log:" >&2;
                                     tail -n 20 "$out/web_map_site.log" >&2; exit 1; }
for tile in "${tiles[@]}"; do
  [[ $tile == *.cog.tif ]] && continue
  gdalinfo "$tile" > "${tile%.tif}.gdalinfo.txt"
done
{
  for tile in "${tiles[@]}"; do
    [[ $tile == *.cog.tif ]] && continue
    printf '%s: %s, %s, pixel %s\n' "$(basename "$tile")" \
      "$(grep -m1 '^Size is' "${tile%.tif}.gdalinfo.txt")" \
      "$(grep -m1 -o 'ID\["EPSG",[0-9]*\]\]$' "${tile%.tif}.gdalinfo.txt" | tail -n1)" \
      "$(grep -m1 '^Pixel Size' "${tile%.tif}.gdalinfo.txt" | sed 's/Pixel Size = //')"
  done
} > "$out/tiles_summary.txt"
cat "$out/tiles_summary.txt"

echo
echo "run-demo: outputs in $out:"
find "$out" -maxdepth 1 -type f ! -name '.*' -printf '%s\t%p\n' | sort -k2 |
  while IFS=$'\t' read -r bytes path; do
    printf '  %8s  %s\n' "$(numfmt --to=iec --suffix=B "$bytes")" "$path"
  done
echo
python3 - "$out/trajectory_summary.json" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
def m(v):
    return 'n/a' if v is None else '%.2f m' % v
dr, usbl, gt = s['dead_reckoning'], s['usbl'], s['ground_truth']
zone = 'EPSG:%s' % s['epsg'] if s['epsg'] else 'no datum'
print('Dive %s (%s): %.1f min, %.0f m travelled' % (s['dive'], zone, s['duration_s'] / 60.0, gt['distance_m']))
print('  rows: ground truth %d, dead reckoning %d, USBL %d' % (gt['rows'], dr['rows'], usbl['rows']))
print('  dead reckoning: RMS error %s, %s at the end' % (m(dr['rms_horizontal_error_m']),
                                                        m(dr['final_horizontal_error_m'])))
print('  USBL fixes:     RMS error %s (median sigma %s)' % (m(usbl['rms_horizontal_error_m']),
                                                           m(usbl['median_horizontal_sigma_m'])))
for key, label in (('fused', 'fused track:   '), ('smoothed', 'RTS smoothed:  ')):
    if s.get(key):
        print('  %s RMS error %s (camera centre)' % (label, m(s[key]['rms_horizontal_error_m'])))
print('Look at %s' % s['plot'])
EOF
echo "Web map of the dive: $out/web/index.html (open it in a browser, or serve $out/web with any web server);"
echo "  for QGIS: $out/web/mosaic.gpkg, or the tiles' virtual mosaic $out/tiles/tile_mosaic.vrt"
