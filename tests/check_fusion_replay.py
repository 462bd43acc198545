#!/usr/bin/env python3
"""Checks the registration + fusion chain on a replayed dive against ground truth (run by fusion_replay.test).

The sample out-and-back dive (the 2D3 report's figure 5 experiment) is replayed with its camera, navigation (dead
reckoning, late USBL fixes, IMU, altimeter) and tf; registration_node turns the images into motion and fusion_node
fuses it with the navigation. The fused camera positions (/mosaic/odometry) are compared with the true camera
centres (/ground_truth/camera_pose of the bag), beside the dead reckoning converted to the camera, and the RTS
smoother's track (~smooth service) beside the filter's. Also checks the filter's consistency (NEES).
"""
import atexit
import math
import os
import signal
import subprocess
import time
import unittest

import numpy as np
import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry, Path
from std_srvs.srv import Trigger
from tf2_msgs.msg import TFMessage

PKG = 'exocet_system_tests'


def read_truth(path):
    """True camera centre (E, N) by stamp (ns), and the image stamps."""
    centres, images = {}, []
    with rosbag.Bag(path) as bag:
        for topic, msg, _ in bag.read_messages(topics=['/ground_truth/camera_pose', '/camera/image_raw/compressed']):
            key = msg.header.stamp.to_nsec()
            if topic == '/ground_truth/camera_pose':
                centres[key] = np.array([msg.pose.position.x, msg.pose.position.y])
            else:
                images.append(key)
    return centres, images


def truth_at(centres_sorted, keys, t_ns):
    """Camera centre at t by linear interpolation of the ground-truth poses."""
    i = int(np.searchsorted(keys, t_ns))
    if i < len(keys) and keys[i] == t_ns:
        return centres_sorted[i]
    if i == 0 or i >= len(keys):
        return None
    w = (t_ns - keys[i - 1]) / float(keys[i] - keys[i - 1])
    return (1 - w) * centres_sorted[i - 1] + w * centres_sorted[i]


class FusionReplayTest(unittest.TestCase):

    def test_fused_track_against_ground_truth(self):
        rospy.init_node('check_fusion_replay')
        bag = rospy.get_param('~bag')
        centres, images = read_truth(bag)
        keys = np.array(sorted(centres))
        centres_sorted = [centres[k] for k in keys]
        odometry = []
        rospy.Subscriber('/mosaic/odometry', Odometry, odometry.append, queue_size=1000)
        smoothed = []
        rospy.Subscriber('/mosaic/path_smoothed', Path, smoothed.append, queue_size=2)
        navigation = []
        rospy.Subscriber('/mosaic/path_navigation', Path, navigation.append, queue_size=2)
        graph = []
        rospy.Subscriber('/mosaic/path_graph', Path, graph.append, queue_size=2)
        fusion_status = {}

        def on_diagnostics(msg):
            for status in msg.status:
                if status.name.endswith('fusion'):
                    fusion_status.update({kv.key: kv.value for kv in status.values})
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=10)
        map_origin = []

        def on_tf(msg):
            for t in msg.transforms:
                if t.header.frame_id == 'utm' and t.child_frame_id == 'map':
                    map_origin.append(np.array([t.transform.translation.x, t.transform.translation.y]))
        rospy.Subscriber('/tf_static', TFMessage, on_tf, queue_size=10)
        time.sleep(1.0)
        topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
                  '/nav/altitude', '/nav/datum', '/tf_static']
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics'] + topics,
                                  start_new_session=True)
        # Never leave a player behind: it would reconnect to the next test's master (same port) and replay there.
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        last_count, last_change = -1, time.time()
        while time.time() - last_change < 20.0:
            if len(odometry) != last_count:
                last_count, last_change = len(odometry), time.time()
            if player.poll() is not None and time.time() - last_change > 3.0:
                break
            time.sleep(0.2)
        rospy.wait_for_service('/fusion/smooth', timeout=10.0)
        reply = rospy.ServiceProxy('/fusion/smooth', Trigger)()
        self.assertTrue(reply.success, reply.message)
        deadline = time.time() + 5.0
        while time.time() < deadline and not smoothed:
            time.sleep(0.1)
        self.assertTrue(smoothed, 'the smoothed path is published')
        # The graph's worker settles after the last input; its path is republished at ~path_rate_hz.
        graph_seen = len(graph)
        deadline = time.time() + 10.0
        while time.time() < deadline and len(graph) < graph_seen + 3:
            time.sleep(0.1)
        self.assertTrue(graph, 'the pose graph path is published (~pose_graph)')

        # One fused position per image pair (image stamps), each against the truth.
        self.assertGreaterEqual(len(odometry), 0.95 * (len(images) - 1))
        errors, nees = [], []
        for o in odometry:
            truth = truth_at(centres_sorted, keys, o.header.stamp.to_nsec())
            if truth is None:
                continue
            err = np.array([o.pose.pose.position.x, o.pose.pose.position.y]) - truth
            cov = np.array([[o.pose.covariance[0], o.pose.covariance[1]], [o.pose.covariance[6], o.pose.covariance[7]]])
            self.assertTrue(np.all(np.isfinite(cov)) and np.linalg.det(cov) > 0.0)
            errors.append(float(np.linalg.norm(err)))
            nees.append(float(err @ np.linalg.solve(cov, err)))
        self.assertTrue(map_origin, 'utm -> map is published on /tf_static')
        origin = map_origin[-1]

        def path_rmse(path):
            e = []
            for p in path.poses:
                truth = truth_at(centres_sorted, keys, p.header.stamp.to_nsec())
                if truth is not None:
                    e.append(np.linalg.norm(np.array([p.pose.position.x, p.pose.position.y]) + origin - truth))
            return math.sqrt(np.mean(np.square(e))), len(e)
        smoothed_rmse, smoothed_count = path_rmse(smoothed[-1])
        graph_rmse, graph_count = path_rmse(graph[-1])

        # Does the map agree with itself: for each key frame of the return, the outbound key frame nearest to it in
        # truth (under 1 m, 30 s earlier at least); the error of their relative position, from the graph and from the
        # filter at the same stamps.
        def positions(path):
            return {p.header.stamp.to_nsec(): np.array([p.pose.position.x, p.pose.position.y]) for p in path.poses}
        graph_at = positions(graph[-1])
        fused_at = {o.header.stamp.to_nsec(): np.array([o.pose.pose.position.x, o.pose.pose.position.y])
                    for o in odometry}
        truth_of = {t: truth_at(centres_sorted, keys, t) for t in graph_at}
        pass_graph, pass_filter = [], []
        for b in graph_at:
            if truth_of[b] is None or b not in fused_at:
                continue
            earlier = [a for a in graph_at if a < b - 30e9 and truth_of[a] is not None and a in fused_at]
            if not earlier:
                continue
            a = min(earlier, key=lambda a: np.linalg.norm(truth_of[a] - truth_of[b]))
            if np.linalg.norm(truth_of[a] - truth_of[b]) > 1.0:
                continue
            truth_rel = truth_of[b] - truth_of[a]
            pass_graph.append(np.linalg.norm(graph_at[b] - graph_at[a] - truth_rel))
            pass_filter.append(np.linalg.norm(fused_at[b] - fused_at[a] - truth_rel))
        nav_rmse, _ = path_rmse(navigation[-1])
        rmse = math.sqrt(np.mean(np.square(errors)))
        mean_nees = float(np.mean(nees))
        in_bounds = float(np.mean([(0.0506 <= v <= 7.38) for v in nees]))
        print('fusion replay: %d fused positions, RMSE %.3f m (max %.3f m), smoothed %.3f m (%d states), dead '
              'reckoning %.3f m; mean NEES %.2f (2 expected), %.0f%% within the 95%% bounds'
              % (len(errors), rmse, max(errors), smoothed_rmse, smoothed_count, nav_rmse, mean_nees, 100 * in_bounds))
        print('fusion replay: passes disagree by %.3f m RMS in the graph, %.3f m in the filter (%d key frames)'
              % (math.sqrt(np.mean(np.square(pass_graph))), math.sqrt(np.mean(np.square(pass_filter))), len(pass_graph)))
        print('fusion replay: pose graph %d key frames, RMSE %.3f m; loops: %s added, %s accepted by the graph, %s '
              'candidates verified, %s key frames searched, last refusal: %s'
              % (graph_count, graph_rmse, fusion_status.get('loops added'), fusion_status.get('graph loops accepted'),
                 fusion_status.get('loop candidates verified'), fusion_status.get('loop key frames searched'),
                 fusion_status.get('loop last refusal')))
        self.assertLess(rmse, 0.3)
        self.assertLessEqual(smoothed_rmse, rmse, 'the smoother uses the future: it does no worse than the filter')
        # A key frame every 0.3 m or 2 s of the track; the graph uses every fix at its stamp, as the smoother does.
        span_s = (odometry[-1].header.stamp - odometry[0].header.stamp).to_sec()
        self.assertGreaterEqual(graph_count, 0.9 * span_s / 2.0)
        self.assertLess(graph_rmse, 0.3)
        # The return pass flies over the outbound one: loops are found, verified and kept by the graph.
        loops_added = int(fusion_status.get('loops added', 0))
        self.assertGreaterEqual(loops_added, 5)
        self.assertGreaterEqual(int(fusion_status.get('graph loops accepted', 0)), 0.9 * loops_added)
        self.assertGreater(len(pass_graph), 5)
        self.assertLess(math.sqrt(np.mean(np.square(pass_graph))), 0.5 * math.sqrt(np.mean(np.square(pass_filter))),
                        'the loops make the return pass agree with the outbound one')
        self.assertGreater(in_bounds, 0.8)
        self.assertTrue(0.5 < mean_nees < 6.0, 'the covariance tells the size of the error')


if __name__ == '__main__':
    rostest.rosrun(PKG, 'fusion_replay', FusionReplayTest)
