#!/usr/bin/env bash
# The chain split as on a ship, on one machine: a "vehicle" network namespace plays the dive's camera and navigation
# (rosbag play standing in for the sensors, and giving the simulated clock), a "surface" namespace runs the ROS
# master and the mosaicking chain; a veth pair is the umbilical, each end shaped to 20 Mbit/s (tc tbf) and dropping
# 2 % of the packets at random each way (nftables numgen), then cut for 10 s in the middle of the dive (the vehicle's
# end set down, then up). ROS_IP is set per host. The images cross compressed (the bag's JPEG, end to end).
#
# Checks: the tiles are valid GeoTIFFs whose surveyed landmarks lie within the bound; the fraction of the bag's frames
# that reached the surface; the time from the link coming back to the first frame received after it (recovery).
# Figures go into out/bench/reliability.json (multihost_frames_delivered_fraction, multihost_recovery_s), the rest of
# that file kept.
#   sudo tools/multihost-test.sh [--bag BAG] [--rate R] [--cut-s S] [--output-dir DIR] [--no-degrade]
# Needs root (network namespaces), iproute2 and nftables (tools/debian-packages.txt). Exit status: 0 the checks
# passed, 1 a check failed, 2 it could not run.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bag=$root/bags/sample_out_and_back.bag
rate=1
cut_s=10
out=$root/out/multihost
degrade=1
while [[ $# -gt 0 ]]; do
  case $1 in
    --bag) bag=$2; shift 2 ;;
    --rate) rate=$2; shift 2 ;;
    --cut-s) cut_s=$2; shift 2 ;;
    --output-dir) out=$2; shift 2 ;;
    --no-degrade) degrade=0; shift ;;
    *) echo "usage: tools/multihost-test.sh [--bag BAG] [--rate R] [--cut-s S] [--output-dir DIR] [--no-degrade]" >&2
       exit 2 ;;
  esac
done
[[ $(id -u) -eq 0 ]] || { echo "multihost-test: needs root (network namespaces)" >&2; exit 2; }
for tool in ip tc nft; do
  command -v $tool >/dev/null || { echo "multihost-test: $tool missing: make deps" >&2; exit 2; }
done
[[ -f $bag ]] || { echo "multihost-test: no bag $bag (make bags)" >&2; exit 2; }
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
set +u
# shellcheck disable=SC1091
source "$root/devel/setup.bash"
set -u

vehicle=exo_vehicle
surface=exo_surface
vehicle_ip=10.77.0.2
surface_ip=10.77.0.1
port=11711
master=http://$surface_ip:$port
on_surface=(ip netns exec $surface env ROS_MASTER_URI=$master ROS_IP=$surface_ip ROS_HOME=$out/ros)
on_vehicle=(ip netns exec $vehicle env ROS_MASTER_URI=$master ROS_IP=$vehicle_ip ROS_HOME=$out/ros)
pids=()

cleanup() {
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null; done
  sleep 2
  for pid in "${pids[@]}"; do kill -KILL "$pid" 2>/dev/null; done
  ip netns pids $surface 2>/dev/null | xargs -r kill -KILL 2>/dev/null
  ip netns pids $vehicle 2>/dev/null | xargs -r kill -KILL 2>/dev/null
  ip netns del $vehicle 2>/dev/null
  ip netns del $surface 2>/dev/null
}
trap cleanup EXIT

rm -rf "$out"
mkdir -p "$out/tiles" "$out/ros"
cleanup
ip netns add $surface
ip netns add $vehicle
ip link add exo_s type veth peer name exo_v
ip link set exo_s netns $surface
ip link set exo_v netns $vehicle
ip netns exec $surface ip addr add $surface_ip/24 dev exo_s
ip netns exec $vehicle ip addr add $vehicle_ip/24 dev exo_v
for ns in $surface $vehicle; do ip netns exec $ns ip link set lo up; done
ip netns exec $surface ip link set exo_s up
ip netns exec $vehicle ip link set exo_v up
# Each namespace knows the other by name (ROS_IP is set, but a node may still be looked up by host name).
if [[ $degrade -eq 1 ]]; then
  for pair in "$surface exo_s" "$vehicle exo_v"; do
    set -- $pair
    ip netns exec "$1" tc qdisc add dev "$2" root tbf rate 20mbit burst 64kb latency 300ms
    ip netns exec "$1" nft -f - <<EOF
table inet umbilical {
  chain inbound { type filter hook input priority 0; iifname "$2" numgen random mod 100 < 2 drop; }
  chain outbound { type filter hook output priority 0; oifname "$2" numgen random mod 100 < 2 drop; }
}
EOF
  done
fi
echo "multihost-test: surface $surface_ip (master $master, chain), vehicle $vehicle_ip (sensors: $bag at ${rate}x)," \
     "$([[ $degrade -eq 1 ]] && echo "20 Mbit/s, 2 % loss each way, " )a ${cut_s} s cut in the middle"

"${on_surface[@]}" roscore -p $port > "$out/roscore.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 100); do
  "${on_surface[@]}" rosparam list > /dev/null 2>&1 && break
  sleep 0.2
done
"${on_surface[@]}" rosparam set /use_sim_time true
"${on_surface[@]}" roslaunch -p $port --wait "$root/src/exocet_mosaic/launch/mosaic_chain.launch" \
  output_dir:="$out/tiles" dive_name:=multihost > "$out/chain.log" 2>&1 &
pids+=($!)
"${on_surface[@]}" /usr/bin/python3 "$root/tools/multihost_monitor.py" --output "$out/arrivals.csv" \
  > "$out/monitor.log" 2>&1 &
monitor=$!
pids+=($monitor)
sleep 8  # the chain's nodes subscribe

duration_s=$(/usr/bin/python3 -c "import rosbag; b = rosbag.Bag('$bag'); print(b.get_end_time() - b.get_start_time())")
topics="/camera/image_raw/compressed /camera/camera_info /nav/odometry /nav/usbl /nav/imu /nav/altitude /nav/datum /tf_static"
start_wall=$(date +%s.%N)
# shellcheck disable=SC2086
"${on_vehicle[@]}" rosbag play --clock -q -r "$rate" --queue=1000 "$bag" --topics $topics > "$out/player.log" 2>&1 &
player=$!
pids+=($player)
cut_at=$(/usr/bin/python3 -c "print(max(5.0, $duration_s / $rate / 2.0 - $cut_s / 2.0))")
sleep "$cut_at"
down_wall=$(date +%s.%N)
ip netns exec $vehicle ip link set exo_v down
sleep "$cut_s"
ip netns exec $vehicle ip link set exo_v up
up_wall=$(date +%s.%N)
echo "multihost-test: link cut at +$(/usr/bin/python3 -c "print(round($down_wall - $start_wall, 1))") s for $cut_s s"
timeout $(/usr/bin/python3 -c "print(int($duration_s / $rate + 300))") tail --pid=$player -f /dev/null
sleep 5
"${on_surface[@]}" timeout 120 rosservice call /tile_writer/flush > "$out/flush.log" 2>&1
kill -INT "$monitor" 2>/dev/null
wait "$monitor" 2>/dev/null
kill -INT "${pids[1]}" 2>/dev/null  # the chain: the tile writer writes its run summary as it exits
timeout 60 tail --pid="${pids[1]}" -f /dev/null
ip netns exec $surface /usr/bin/python3 - "$out" "$bag" "$down_wall" "$up_wall" "$root" <<'PY'
import csv, json, os, sys
import rosbag
sys.path.insert(0, os.path.join(sys.argv[5], 'src', 'exocet_mosaic', 'python'))
from exocet_mosaic import tile_analysis

out, bag, down, up = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
sent = rosbag.Bag(bag).get_message_count('/camera/image_raw/compressed')
arrivals = list(csv.DictReader(open(os.path.join(out, 'arrivals.csv'))))
after = sorted(float(r['wall_s']) for r in arrivals if float(r['wall_s']) > up)
recovery_s = after[0] - up if after else None
# What the tile writer received (its run summary at exit), else the registrations seen (one per image but the first).
run = os.path.join(out, 'tiles', 'run_summary.json')
received = json.load(open(run)).get('images_received') if os.path.exists(run) else None
if received is None:
    received = len({r['stamp_s'] for r in arrivals}) + 1
delivered = received / float(sent)
tiles = tile_analysis.read_tiles(os.path.join(out, 'tiles'))
stem = bag[:-len('.bag')]
marks = [dict(id=r['id'], easting_m=float(r['easting_m']), northing_m=float(r['northing_m']),
              size_m=float(r['size_m'])) for r in csv.DictReader(open(stem + '.landmarks.csv'))]
found = []  # each surveyed checker where a tile holds data, found near its place (as tiles_replay.test does)
for m in marks:
    for t in tiles:
        if t.has_data_at(m['easting_m'], m['northing_m']):
            saddle = tile_analysis.find_checker_saddle(t, m['easting_m'], m['northing_m'], m['size_m'], search_m=0.5)
            if saddle is not None:
                found.append({'error_m': ((saddle[0] - m['easting_m']) ** 2 + (saddle[1] - m['northing_m']) ** 2) ** 0.5})
sigmas = [float(t.metadata.get('EXOCET_POSITION_SIGMA_M', 'nan')) for t in tiles]
sigmas = sorted(s for s in sigmas if s == s)
bound = max(3.0 * (sigmas[len(sigmas) // 2] if sigmas else 0.0), 0.05)
worst = max((o['error_m'] for o in found), default=None)
summary = {'frames_sent': sent, 'frames_received': received, 'delivered_fraction': round(delivered, 4),
           'recovery_s': None if recovery_s is None else round(recovery_s, 2), 'tiles': len(tiles),
           'landmarks_found': len(found), 'landmark_error_max_m': worst, 'landmark_bound_m': round(bound, 4)}
print('multihost-test: %s' % json.dumps(summary))
json.dump(summary, open(os.path.join(out, 'multihost.json'), 'w'), indent=2)
path = os.path.join(os.path.dirname(out), 'bench', 'reliability.json')
os.makedirs(os.path.dirname(path), exist_ok=True)
figures = json.load(open(path)) if os.path.exists(path) else {}
figures.update({'multihost_frames_delivered_fraction': summary['delivered_fraction'],
                'multihost_recovery_s': summary['recovery_s']})
tmp = path + '.tmp'
json.dump(figures, open(tmp, 'w'), indent=2, sort_keys=True)
os.replace(tmp, path)
failures = []
if len(tiles) < 2:
    failures.append('fewer than 2 tiles')
if not found:
    failures.append('no landmark found in the tiles')
elif worst > bound:
    failures.append('a landmark %.3f m off (bound %.3f m)' % (worst, bound))
if recovery_s is None:
    failures.append('no frame arrived after the link came back')
if failures:
    print('multihost-test: FAILED: ' + '; '.join(failures))
    sys.exit(1)
print('multihost-test: passed')
PY
