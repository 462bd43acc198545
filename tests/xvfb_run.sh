#!/usr/bin/env bash
# Runs a command on a virtual X display of its own: xvfb_run.sh DISPLAY_NUMBER COMMAND [ARGS...]. The display
# (1600x1000, 24 bits) stays while the command runs and goes with it; a test takes screenshots of it with
# `import -display :N -window root FILE.png`. Used as rviz's launch-prefix by rviz_replay.test.
set -u
number=$1
shift
if [[ -e /tmp/.X11-unix/X$number ]]; then
  echo "xvfb_run: display :$number is taken" >&2
  exit 1
fi
Xvfb ":$number" -screen 0 1600x1000x24 -nolisten tcp &
xvfb=$!
child=""
stop() {
  [[ -n $child ]] && kill "$child" 2>/dev/null && wait "$child" 2>/dev/null
  kill "$xvfb" 2>/dev/null
  wait "$xvfb" 2>/dev/null
}
trap stop EXIT
trap 'exit 130' INT TERM
for _ in $(seq 1 100); do
  [[ -e /tmp/.X11-unix/X$number ]] && break
  sleep 0.1
done
[[ -e /tmp/.X11-unix/X$number ]] || { echo "xvfb_run: Xvfb did not start on :$number" >&2; exit 1; }
DISPLAY=":$number" "$@" &
child=$!
wait "$child"
status=$?
child=""
exit $status
