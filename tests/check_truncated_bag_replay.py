#!/usr/bin/env python3
"""A truncated bag replayed as a user would (run by truncated_bag_replay.test).

The sample out-and-back dive's bag file is cut in the middle (bad_recordings.truncate_bag), as a recorder that died
or a disk that filled leaves it: no index, a chunk cut short; `rosbag play` alone refuses it. `roslaunch exocet_mosaic
replay.launch` on it (on the test's master) must:
- say it (a warning from the replay_watcher, and its /diagnostics status "replay_watcher: bag" at WARN);
- process what is readable: tiles over the images up to a few seconds before the cut, the run summary with tiles and
  no reason;
- end by itself, no node of the chain crashing (each keeps its pid from its start to the end of the replay).
The verdict goes to out/bench/bad_recordings.json as "truncated_bag", the totals to reliability.json.
"""
import atexit
import json
import os
import re
import signal
import subprocess
import time
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rosgraph_msgs.msg import Log

from bad_recordings import truncate_bag
from exocet_mosaic.testing import node_pid
from exocet_mosaic.reliability import record_bad_recordings, workspace_bench_dir
from exocet_mosaic.tile_analysis import Tile, tile_paths

NODES = ['registration', 'fusion', 'tile_writer']




class TruncatedBagReplayTest(unittest.TestCase):

    def test_truncated_bag(self):
        survived = False
        try:
            self.replay_truncated_bag()
            survived = True
        finally:
            record_bad_recordings({'truncated_bag': survived}, workspace_bench_dir(__file__))

    def replay_truncated_bag(self):
        rospy.init_node('check_truncated_bag_replay')
        source = rospy.get_param('~bag')
        output = rospy.get_param('~output_dir')
        tiles_dir = os.path.join(output, 'tiles')
        os.makedirs(tiles_dir, exist_ok=True)
        bag = os.path.join(output, 'truncated.bag')
        truncate_bag(source, bag, 0.5)
        with self.assertRaises(rosbag.ROSBagUnindexedException):
            rosbag.Bag(bag)
        with rosbag.Bag(source) as whole:
            image_stamps = sorted(m.header.stamp.to_sec() for _, m, _ in whole.read_messages('/camera/camera_info'))
        logs, warnings = [], []
        rospy.Subscriber('/rosout', Log, logs.append, queue_size=1000)

        def on_diagnostics(msg):
            warnings.extend(s for s in msg.status if s.name == 'replay_watcher: bag')
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)

        log = open(os.path.join(output, 'replay.log'), 'w')
        launch = subprocess.Popen(['roslaunch', 'exocet_mosaic', 'replay.launch', 'bag:=' + bag,
                                   'output_dir:=' + tiles_dir, 'rate:=4', 'ground_truth:=false'],
                                  stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        atexit.register(lambda: launch.poll() is None and os.killpg(launch.pid, signal.SIGKILL))
        # Until the tile writer's normal end (its run summary), each node keeps the pid it started with.
        summary_path = os.path.join(tiles_dir, 'run_summary.json')
        seen = {n: set() for n in NODES}
        deadline = time.time() + 180.0
        while launch.poll() is None and time.time() < deadline:
            if not os.path.exists(summary_path):
                for node in NODES:
                    pid = node_pid(node)
                    if pid is not None:
                        seen[node].add(pid)
            time.sleep(0.2)
        status = launch.poll()
        log.close()
        self.assertEqual(status, 0, 'replay.launch ends by itself (see %s/replay.log)' % output)
        self.assertEqual({n: len(p) for n, p in seen.items()}, {n: 1 for n in NODES},
                         'no node of the chain crashed (and was respawned): %s' % seen)

        said = [m for m in logs if m.name == '/replay_watcher' and m.level >= Log.WARN and 'truncated' in m.msg]
        self.assertTrue(said, 'the replay_watcher warns that the bag is truncated')
        self.assertTrue(warnings and warnings[0].level == DiagnosticStatus.WARN and 'truncated' in warnings[0].message,
                        'and says so on /diagnostics')
        match = re.search(r'(\d+) messages over ([0-9.]+) s', said[0].msg)
        self.assertIsNotNone(match, said[0].msg)
        readable_s = float(match.group(2))
        print('truncated bag: %s' % said[0].msg)

        summary = json.load(open(os.path.join(tiles_dir, 'run_summary.json')))
        self.assertIsNone(summary['reason'], summary)
        self.assertGreaterEqual(summary['tiles_written'], 1, summary)
        tiles = [Tile(p) for p in tile_paths(tiles_dir)]
        self.assertEqual(len(tiles), summary['tiles_written'])
        spans = [(float(t.metadata['EXOCET_START_TIME_S']), float(t.metadata['EXOCET_END_TIME_S'])) for t in tiles]
        start = image_stamps[0]
        readable = [s for s in image_stamps if s <= start + readable_s - 3.0]
        covered = sum(1 for s in readable if any(a <= s <= b for a, b in spans))
        last_tiled_s = max(b for _, b in spans) - start
        print('truncated bag: %d tiles over %.1f s of dive of the %.1f s readable; %d of %d images covered' %
              (len(tiles), last_tiled_s, readable_s, covered, len(readable)))
        self.assertGreater(last_tiled_s, readable_s - 3.0, 'tiled up to the cut')
        self.assertGreater(covered, 0.9 * len(readable))
        self.assertFalse(os.path.exists(os.path.join(tiles_dir, '.replay_watcher')), 'the reindexed copy is removed')


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'truncated_bag_replay', TruncatedBagReplayTest)
