#!/usr/bin/env python3
"""Checks the trajectories logged from a replayed dive bag against the bag itself (run by demo_replay.test).

Waits for the replay to end (the /clock reaches the bag's last message, then a second), then checks that
ground_truth.csv, navigation.csv and usbl_fixes.csv have one row per message of their topic in the bag, none lost at
the start or the end, with every value equal to the bag's, and that each USBL fix, converted to UTM, lies within
5 sigma of the ground truth at its measurement time. All waits are on the wall clock: the sim clock stops with the
bag.
"""
import bisect
import csv
import math
import os
import shutil
import threading
import time
import unittest

import rosbag
import rospy
import rostest
from exocet_mosaic.testing import lat_lon_to_utm, stamp_text
from rosgraph_msgs.msg import Clock

PKG = 'exocet_system_tests'
GROUND_TRUTH = '/ground_truth/odometry'
NAVIGATION = '/nav/odometry'
USBL = '/nav/usbl'
DATUM = '/nav/datum'


def roll_pitch_yaw_deg(q):
    """tf2's getRPY convention (R = Rz(yaw) Ry(pitch) Rx(roll)), as the logger computes it."""
    norm = math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2)
    x, y, z, w = q.x / norm, q.y / norm, q.z / norm, q.w / norm
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return [math.degrees(v) for v in (roll, pitch, yaw)]


def read_bag(path):
    """Messages of the logged topics in bag order, as (record time, message) lists per topic."""
    messages = {GROUND_TRUTH: [], NAVIGATION: [], USBL: [], DATUM: []}
    with rosbag.Bag(path) as bag:
        for topic, msg, t in bag.read_messages(topics=list(messages)):
            messages[topic].append((t, msg))
    return messages


def read_rows(path):
    if not os.path.exists(path):
        return None, []
    with open(path, newline='') as f:
        lines = list(csv.reader(f))
    return (lines[0], lines[1:]) if lines else (None, [])


class DemoReplayTest(unittest.TestCase):

    def setUp(self):
        self.clock_lock = threading.Lock()
        self.clock = None            # latest /clock
        self.clock_changed = None    # wall time of its latest change
        self.subscriber = rospy.Subscriber('/clock', Clock, self.on_clock, queue_size=100)

    def on_clock(self, msg):
        with self.clock_lock:
            if self.clock is None or msg.clock != self.clock:
                self.clock = msg.clock
                self.clock_changed = time.monotonic()

    def wait_for_end_of_bag(self, end_time, duration_s, rate):
        """Returns when the /clock has reached the bag's last message (or stopped just short of it: rosbag play
        publishes the clock at its own pace), plus one second."""
        started = time.monotonic()
        limit_s = 3.0 * duration_s / rate + 120.0
        while True:
            with self.clock_lock:
                clock, changed = self.clock, self.clock_changed
            now = time.monotonic()
            if clock is not None and clock >= end_time - rospy.Duration(0.5):
                break
            if clock is not None and now - changed > 5.0:
                break  # the replay ended with the clock a little short of the last stamp: the row counts will tell
            if clock is None and now - started > 60.0:
                self.fail('no /clock after 60 s: did rosbag play start? (see the launch output)')
            if now - started > limit_s:
                self.fail('the replay did not end within %.0f s: /clock at %s, the bag ends at %s'
                          % (limit_s, clock, end_time))
            time.sleep(0.05)
        time.sleep(1.0)

    def wait_rows(self, path, count, timeout_s=20.0):
        deadline = time.monotonic() + timeout_s
        header, rows = read_rows(path)
        while len(rows) < count and time.monotonic() < deadline:
            time.sleep(0.1)
            header, rows = read_rows(path)
        time.sleep(0.5)  # a row too many would come with the next flush
        return read_rows(path)

    def check_odometry(self, path, messages, with_sigma):
        header, rows = self.wait_rows(path, len(messages))
        self.assertIsNotNone(header, '%s is missing' % path)
        self.assertEqual(len(rows), len(messages),
                         '%s: %d rows for %d messages in the bag (first logged %s, first in the bag %s; last logged '
                         '%s, last in the bag %s)'
                         % (path, len(rows), len(messages), rows[0][0] if rows else None,
                            stamp_text(messages[0][1].header.stamp) if messages else None,
                            rows[-1][0] if rows else None,
                            stamp_text(messages[-1][1].header.stamp) if messages else None))
        for number, (row, (_, msg)) in enumerate(zip(rows, messages), start=2):
            where = '%s:%d' % (path, number)
            self.assertEqual(row[0], stamp_text(msg.header.stamp), where)
            p = msg.pose.pose.position
            self.assertEqual([float(v) for v in row[1:4]], [p.x, p.y, p.z], where)
            for got, want in zip(row[4:7], roll_pitch_yaw_deg(msg.pose.pose.orientation)):
                self.assertAlmostEqual(float(got), want, delta=1e-9, msg=where)
            if with_sigma:
                c = msg.pose.covariance
                self.assertTrue(math.isclose(float(row[7]), math.sqrt((c[0] + c[7]) / 2.0), rel_tol=1e-12,
                                             abs_tol=1e-15), where)
                self.assertTrue(math.isclose(float(row[8]), math.sqrt(c[14]), rel_tol=1e-12, abs_tol=1e-15), where)
        return rows

    def test_replay_logs_every_message(self):
        bag_path = rospy.get_param('~bag')
        rate = float(rospy.get_param('~rate'))
        output_dir = rospy.get_param('~output_dir')
        # Not os.path.normpath: the default path goes through the src/exocet_system_tests symlink and '..'.
        if not os.path.isfile(bag_path):
            self.fail("no bag %s: make it with 'make bags'" % bag_path)
        bag = read_bag(bag_path)
        for topic in (GROUND_TRUTH, NAVIGATION, USBL, DATUM):
            self.assertTrue(bag[topic], '%s has no message on %s' % (bag_path, topic))
        all_times = [t for topic in bag for t, _ in bag[topic]]
        begin, end = min(all_times), max(all_times)
        self.wait_for_end_of_bag(end, (end - begin).to_sec(), rate)

        truth_rows = self.check_odometry(os.path.join(output_dir, 'ground_truth.csv'), bag[GROUND_TRUTH], False)
        self.check_odometry(os.path.join(output_dir, 'navigation.csv'), bag[NAVIGATION], True)

        datum = bag[DATUM][-1][1]
        with open(os.path.join(output_dir, 'datum.json')) as f:
            self.assertIn('"epsg": %d' % datum.epsg, f.read())

        path = os.path.join(output_dir, 'usbl_fixes.csv')
        header, rows = self.wait_rows(path, len(bag[USBL]))
        self.assertEqual(len(rows), len(bag[USBL]), '%s: %d rows for %d fixes in the bag'
                         % (path, len(rows), len(bag[USBL])))
        truth_t = [float(r[0]) for r in truth_rows]
        truth_e = [float(r[1]) for r in truth_rows]
        truth_n = [float(r[2]) for r in truth_rows]
        # arrival_s is the logger's clock at reception: the bag's record time, late by the replay's jitter (the
        # clock ticks every 1 ms of wall time, i.e. rate ms of sim time).
        arrival_tolerance_s = max(1.0, 0.25 * rate)
        worst_ratio = 0.0
        for number, (row, (recorded, msg)) in enumerate(zip(rows, bag[USBL]), start=2):
            where = '%s:%d' % (path, number)
            self.assertEqual(row[0], stamp_text(msg.header.stamp), where)
            self.assertLess(abs(float(row[1]) - recorded.to_sec()), arrival_tolerance_s,
                            '%s: arrival_s %s, recorded at %s' % (where, row[1], stamp_text(recorded)))
            self.assertEqual(float(row[2]), msg.latitude, where)
            self.assertEqual(float(row[3]), msg.longitude, where)
            east_m, north_m = lat_lon_to_utm(msg.latitude, msg.longitude, datum.utm_zone, datum.northern_hemisphere)
            self.assertAlmostEqual(float(row[4]), east_m, delta=1e-3, msg=where)
            self.assertAlmostEqual(float(row[5]), north_m, delta=1e-3, msg=where)
            sigma_m = math.sqrt((msg.position_covariance[0] + msg.position_covariance[4]) / 2.0)
            self.assertTrue(math.isclose(float(row[6]), sigma_m, rel_tol=1e-12), where)
            # Within 5 sigma of the ground truth at the measurement time.
            t = float(row[0])
            self.assertTrue(truth_t[0] <= t <= truth_t[-1], '%s: fix at %s outside the ground truth' % (where, t))
            i = min(max(bisect.bisect_left(truth_t, t), 1), len(truth_t) - 1)
            w = (t - truth_t[i - 1]) / (truth_t[i] - truth_t[i - 1]) if truth_t[i] > truth_t[i - 1] else 0.0
            e_true = truth_e[i - 1] + w * (truth_e[i] - truth_e[i - 1])
            n_true = truth_n[i - 1] + w * (truth_n[i] - truth_n[i - 1])
            error_m = math.hypot(float(row[4]) - e_true, float(row[5]) - n_true)
            self.assertGreater(sigma_m, 0.0, where)
            self.assertLessEqual(error_m, 5.0 * sigma_m, '%s: %.2f m from the ground truth, sigma %.2f m'
                                 % (where, error_m, sigma_m))
            worst_ratio = max(worst_ratio, error_m / sigma_m)
        rospy.loginfo('demo_replay: %d ground truth, %d navigation, %d USBL rows match the bag; worst USBL error '
                      '%.2f sigma', len(truth_rows), len(bag[NAVIGATION]), len(rows), worst_ratio)
        shutil.rmtree(output_dir, ignore_errors=True)  # kept when a check fails, to look at


if __name__ == '__main__':
    rospy.init_node('check_demo_replay')
    rostest.rosrun(PKG, 'demo_replay', DemoReplayTest)
