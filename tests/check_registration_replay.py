#!/usr/bin/env python3
"""Checks registration_node's motions on a replayed dive against ground truth (run by registration_replay.test).

The bag holds, for each image, the true camera pose (/ground_truth/camera_pose, UTM) and the distance along the
optical axis to the flat seabed (/ground_truth/altitude); with the intrinsics of /camera/camera_info they give the
exact motion of every pixel between two images. Waits (wall clock) until the motions stop arriving after the
replay's last image, then checks: one message per consecutive image pair, stamps matching the images, few failures,
corner-transfer errors, and the node's peak resident memory.
"""
import math
import atexit
import os
import signal
import subprocess
import time
import unittest
import xmlrpc.client

import numpy as np
import rosbag
import rosgraph
import rospy
import rostest
from exocet_msgs.msg import ImageMotion

PKG = 'exocet_system_tests'


def quaternion_matrix(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def read_truth(path):
    """Per image stamp: (world_from_camera rotation, camera centre, seabed height in the world frame); K; size."""
    poses, altitudes, stamps, info = {}, {}, [], None
    with rosbag.Bag(path) as bag:
        for topic, msg, _ in bag.read_messages(topics=['/ground_truth/camera_pose', '/ground_truth/altitude',
                                                       '/camera/camera_info', '/camera/image_raw/compressed']):
            key = msg.header.stamp.to_nsec()
            if topic == '/ground_truth/camera_pose':
                p = msg.pose.position
                poses[key] = (quaternion_matrix(msg.pose.orientation), np.array([p.x, p.y, p.z]))
            elif topic == '/ground_truth/altitude':
                altitudes[key] = msg.range
            elif topic == '/camera/camera_info':
                info = msg
            else:
                stamps.append(key)
    truth = {}
    for key in stamps:
        rotation, centre = poses[key]
        # The altitude runs along the optical axis (camera z) down to the seabed plane.
        seabed_z = centre[2] + altitudes[key] * rotation[2, 2]
        truth[key] = (rotation, centre, seabed_z)
    return stamps, truth, np.array(info.K).reshape(3, 3), (info.width, info.height)


def transfer(k, a, b, pixel):
    """Where `pixel` of camera A lands in camera B through the seabed plane."""
    ra, ca, zs = a
    rb, cb, _ = b
    ray = ra @ np.linalg.solve(k, np.array([pixel[0], pixel[1], 1.0]))
    point = ca + (zs - ca[2]) / ray[2] * ray
    p = k @ (rb.T @ (point - cb))
    return p[:2] / p[2]


def node_peak_rss_mb(node_name):
    master = rosgraph.Master('/check_registration_replay')
    uri = master.lookupNode(node_name)
    code, _, pid = xmlrpc.client.ServerProxy(uri).getPid('/check_registration_replay')
    with open('/proc/%d/status' % pid) as f:
        for line in f:
            if line.startswith('VmHWM:'):
                return int(line.split()[1]) / 1024.0
    return float('nan')


class RegistrationReplayTest(unittest.TestCase):

    def test_motions_against_ground_truth(self):
        rospy.init_node('check_registration_replay')
        bag = rospy.get_param('~bag')
        stamps, truth, k, (width, height) = read_truth(bag)
        motions = []
        rospy.Subscriber('/mosaic/motion', ImageMotion, motions.append, queue_size=1000)
        time.sleep(1.0)
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics',
                                   '/camera/image_raw/compressed', '/camera/camera_info'], start_new_session=True)
        # Never leave a player behind: it would reconnect to the next test's master (same port) and replay there.
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        # Wall-clock wait: until the last pair's motion is in, or nothing new has come for 20 s.
        last_count, last_change = -1, time.time()
        while time.time() - last_change < 20.0:
            if len(motions) != last_count:
                last_count, last_change = len(motions), time.time()
            if motions and motions[-1].header.stamp.to_nsec() == stamps[-1]:
                break
            time.sleep(0.2)
        time.sleep(1.0)

        self.assertEqual(len(motions), len(stamps) - 1, 'one motion per consecutive image pair')
        index = {s: i for i, s in enumerate(stamps)}
        corners = [(0.0, 0.0), (width - 1.0, 0.0), (0.0, height - 1.0), (width - 1.0, height - 1.0)]
        errors, failures = [], []
        for m in motions:
            cur, prev = m.header.stamp.to_nsec(), m.previous_stamp.to_nsec()
            self.assertEqual(index[cur], index[prev] + 1, 'a motion relates two consecutive images')
            self.assertEqual((m.image_width, m.image_height), (width, height))
            if m.failed:
                failures.append(m.failure)
                continue
            h = np.array(m.matrix).reshape(3, 3)
            n = len(m.parameters)
            self.assertEqual(len(m.covariance), n * n)
            self.assertTrue(all(math.isfinite(v) for v in m.covariance))
            worst = 0.0
            for c in corners:
                est = h @ np.array([c[0], c[1], 1.0])
                true = transfer(k, truth[prev], truth[cur], c)
                worst = max(worst, float(np.linalg.norm(est[:2] / est[2] - true)))
            errors.append(worst)
        errors = np.array(errors)
        median, p95 = float(np.median(errors)), float(np.percentile(errors, 95))
        gross = int(np.sum(errors > 2.0))
        rss = node_peak_rss_mb(rospy.get_param('~node'))
        print('registration replay: %d motions, %d failed %s, corner error median %.3f px, p95 %.3f px, max %.3f '
              'px, %d gross; node peak RSS %.0f MB' % (len(motions), len(failures), sorted(set(failures)), median,
                                                       p95, float(errors.max()), gross, rss))
        self.assertLessEqual(len(failures), 0.02 * len(motions), 'at most 2% of the pairs fail')
        # JPEG at quality 95, 5 frames/s (about 20 px between frames), lamp cone and marine snow.
        self.assertLess(median, 0.2)
        self.assertLess(p95, 0.6)
        self.assertEqual(gross, 0, 'no error above 2 px reported as a success')
        self.assertLess(rss, 200.0, 'peak resident memory of the node')


if __name__ == '__main__':
    rostest.rosrun(PKG, 'registration_replay', RegistrationReplayTest)
