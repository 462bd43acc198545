#!/usr/bin/env python3
"""Bad recordings replayed through the chain (run by bad_recordings_replay.test).

The sample out-and-back dive is copied with six faults, each in its own window of the dive (bad_recordings.FAULTS):
corrupt JPEGs, images of another size, NaN navigation, navigation stamped backwards, duplicated stamps, a camera_info
that changes. The copy is replayed once through registration, fusion and tile writer (mosaic_chain.launch); then each
fault is one test case that checks, in its window:
- a warning: the node that meets the fault logs it (WARN or ERROR on /rosout), throttled: fewer messages than faulty
  inputs;
- a diagnostic: that node's /diagnostics counts it (the counter named rises over the window);
- no crash: every node of the chain keeps the pid it had before the replay (a respawn would hide a crash);
- the rest of the dive processed: the fused odometry goes on after the window and the tiles cover the images after it.
Each fault's verdict goes to out/bench/bad_recordings.json and the totals to reliability.json (bad_recordings_tried,
bad_recordings_survived).
"""
import atexit
import os
import re
import signal
import subprocess
import time
import unittest

import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import Tile as TileMsg
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from std_srvs.srv import Trigger

from bad_recordings import fault_named, write_faulty_bag
from exocet_mosaic.testing import node_pid
from exocet_mosaic.reliability import record_bad_recordings, workspace_bench_dir

NODES = ['registration', 'fusion', 'tile_writer']
# What meets each fault: (node, the /diagnostics counters of which at least one rises, a pattern of its log message,
# how many faulty inputs the window holds).
EXPECTED = {
    'corrupt_jpeg': [('registration', ['images rejected'], r'cannot be decoded', 10)],
    'image_size': [('registration', ['sequence restarts'], r'image size changed', 10),
                   ('tile_writer', ['images rejected'], r"not the camera_info's", 10)],
    'nan_navigation': [('fusion', ['rejected inputs: dead reckoning'], r'dead reckoning rejected', 20),
                       ('fusion', ['rejected inputs: imu'], r'imu rejected', 100),
                       ('fusion', ['rejected inputs: altitude'], r'altitude rejected', 20)],
    'backwards_navigation': [('fusion', ['invalid: dead reckoning'], r'dead reckoning invalid.*stamp order', 20),
                             ('fusion', ['rejected inputs: imu'], r'imu rejected.*out of order', 100)],
    'duplicated_stamps': [('registration', ['images rejected'], r'duplicated stamp', 10),
                          ('tile_writer', ['images rejected'], r'duplicated stamp', 10),
                          ('fusion', ['invalid: dead reckoning'], r'dead reckoning invalid', 20)],
    'camera_info_change': [('registration', ['sequence restarts'], r'camera calibration changed', 135)],
}




class BadRecordingsReplayTest(unittest.TestCase):
    results = {}

    @classmethod
    def setUpClass(cls):
        rospy.init_node('check_bad_recordings_replay')
        source = rospy.get_param('~bag')
        output = rospy.get_param('~output_dir')
        os.makedirs(output, exist_ok=True)
        cls.bag = os.path.join(output, 'faulty.bag')
        cls.bag_start = write_faulty_bag(source, cls.bag)
        with rosbag.Bag(cls.bag) as bag:
            cls.bag_end = bag.get_end_time()
            cls.image_stamps = sorted({m.header.stamp.to_sec() for _, m, _ in
                                       bag.read_messages('/camera/camera_info')})
        cls.logs, cls.diagnostics, cls.tiles, cls.odometry = [], [], [], []
        rospy.Subscriber('/rosout', Log, cls.logs.append, queue_size=1000)  # rostest runs no rosout node

        def on_diagnostics(msg):
            now = rospy.get_rostime().to_sec()
            for s in msg.status:
                cls.diagnostics.append((now, s.name, {kv.key: kv.value for kv in s.values}))
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        rospy.Subscriber('/mosaic/tile', TileMsg, cls.tiles.append, queue_size=100)
        rospy.Subscriber('/mosaic/odometry', Odometry, lambda m: cls.odometry.append(m.header.stamp.to_sec()),
                         queue_size=1000)
        deadline = time.time() + 60.0
        while time.time() < deadline and any(node_pid(n) is None for n in NODES):
            time.sleep(0.2)
        cls.pids_before = {n: node_pid(n) for n in NODES}
        time.sleep(1.0)
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', cls.bag, '--topics',
                                   '/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl',
                                   '/nav/imu', '/nav/altitude', '/nav/datum', '/tf_static'], start_new_session=True)
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        last, last_change = -1, time.time()
        while time.time() - last_change < 30.0:
            if len(cls.odometry) != last:
                last, last_change = len(cls.odometry), time.time()
            if player.poll() is not None and time.time() - last_change > 4.0:
                break
            time.sleep(0.1)
        rospy.wait_for_service('/tile_writer/flush', timeout=10.0)
        rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        time.sleep(3.0)  # the last /diagnostics and log messages
        cls.pids_after = {n: node_pid(n) for n in NODES}

    @classmethod
    def tearDownClass(cls):
        record_bad_recordings(cls.results, workspace_bench_dir(__file__))

    def counter(self, node, key, at_s, after):
        """The node's counter `key` in its last report before `at_s` (after=False) or first one after it."""
        reports = [(t, v) for t, name, v in self.diagnostics if name.startswith(node + ':') and key in v]
        if after:
            reports = [r for r in reports if r[0] >= at_s]
            return float(reports[0][1][key]) if reports else None
        reports = [r for r in reports if r[0] <= at_s]
        return float(reports[-1][1][key]) if reports else 0.0

    def check_fault(self, name):
        fault = fault_named(name)
        start = self.bag_start + fault.start_s
        end = self.bag_start + (fault.end_s if fault.end_s is not None else fault.start_s + 5.0)
        survived = False
        try:
            self.assertEqual(self.pids_after, self.pids_before, 'no node of the chain crashed (and was respawned)')
            for node, keys, pattern, faulty in EXPECTED[name]:
                messages = [m for m in self.logs if m.name == '/' + node and m.level >= Log.WARN and
                            start - 1.0 <= m.header.stamp.to_sec() <= end + 5.0 and re.search(pattern, m.msg)]
                self.assertGreaterEqual(len(messages), 1, '%s logs the %s (/%s matching "%s")' %
                                        (node, name, node, pattern))
                self.assertLess(len(messages), faulty, '%s throttles its messages about the %s' % (node, name))
                rises = {}
                for key in keys:
                    before = self.counter(node, key, start - 0.5, False)
                    after = self.counter(node, key, end + 3.0, True)
                    rises[key] = None if after is None else after - before
                self.assertTrue(any(r and r > 0 for r in rises.values()),
                                '%s counts the %s on /diagnostics: %s' % (node, name, rises))
                print('bad recordings: %s: %s logged %d message(s) "%s"..., counters %s' %
                      (name, node, len(messages), messages[0].msg[:100], rises))
            # The rest of the dive: fused on, and tiled.
            self.assertTrue(any(s > end + 5.0 for s in self.odometry), 'the fusion goes on after the %s' % name)
            spans = [(m.start_time.to_sec(), m.end_time.to_sec()) for m in self.tiles]
            later = [s for s in self.image_stamps if end + 2.0 <= s <= end + 10.0]
            covered = sum(1 for s in later if any(a <= s <= b for a, b in spans))
            self.assertGreater(covered, 0.8 * len(later), 'the tiles cover the images after the %s (%d of %d)' %
                               (name, covered, len(later)))
            survived = True
        finally:
            self.results[name] = survived

    def test_corrupt_jpeg(self):
        self.check_fault('corrupt_jpeg')

    def test_image_of_another_size(self):
        self.check_fault('image_size')

    def test_nan_navigation(self):
        self.check_fault('nan_navigation')

    def test_backwards_navigation_stamps(self):
        self.check_fault('backwards_navigation')

    def test_duplicated_stamps(self):
        self.check_fault('duplicated_stamps')

    def test_camera_info_change(self):
        self.check_fault('camera_info_change')


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'bad_recordings_replay', BadRecordingsReplayTest)
