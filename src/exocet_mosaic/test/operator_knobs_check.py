#!/usr/bin/env python3
"""Checks odometry_path_node (ground truth -> rviz path) and the live knobs of registration_node and fusion_node."""
import time
import unittest

import rospy
import tf2_ros
from geometry_msgs.msg import TransformStamped
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from dynamic_reconfigure.client import Client
from nav_msgs.msg import Odometry, Path


def odometry(stamp_s, x_m, y_m):
    m = Odometry()
    m.header.stamp = rospy.Time(stamp_s)
    m.header.frame_id = 'utm'
    m.child_frame_id = 'base_link'
    m.pose.pose.position.x, m.pose.pose.position.y = x_m, y_m
    m.pose.pose.orientation.w = 1.0
    return m


class OperatorKnobsTest(unittest.TestCase):

    def setUp(self):
        rospy.init_node('operator_knobs_check', anonymous=True)
        self.statuses = {}

        def on_diagnostics(msg):
            for s in msg.status:
                self.statuses[s.name] = {kv.key: kv.value for kv in s.values}
                self.statuses[s.name]['_message'] = s.message
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)

    def wait_for(self, predicate, timeout_s=20.0):
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            if predicate():
                return True
            time.sleep(0.1)
        return False

    def status_of(self, fragment):
        for name, values in self.statuses.items():
            if fragment in name:
                return values
        return None

    def test_ground_truth_path(self):
        paths = []
        rospy.Subscriber('/mosaic/ground_truth_path', Path, paths.append, queue_size=10)
        pub = rospy.Publisher('/ground_truth/odometry', Odometry, queue_size=100)
        self.assertTrue(self.wait_for(lambda: pub.get_num_connections() > 0))
        # The path is drawn in map (rviz's single precision): the poses before utm -> map is known wait for it.
        broadcaster = tf2_ros.StaticTransformBroadcaster()
        for k in range(20):
            pub.publish(odometry(100.0 + 0.2 * k, 500000.0 + 0.5 * k, 4700000.0 - 0.25 * k))
            if k == 7:
                pub.publish(odometry(101.5, float('nan'), 4700000.0))
            if k == 4:
                t = TransformStamped()
                t.header.stamp = rospy.Time.now()
                t.header.frame_id = 'utm'
                t.child_frame_id = 'map'
                t.transform.translation.x = 500000.0
                t.transform.translation.y = 4700000.0
                t.transform.rotation.w = 1.0
                broadcaster.sendTransform(t)
                time.sleep(0.5)
            time.sleep(0.01)
        self.assertTrue(self.wait_for(lambda: paths and len(paths[-1].poses) == 20), 'path of 20 poses not published')
        path = paths[-1]
        self.assertEqual(path.header.frame_id, 'map')
        for k, pose in enumerate(path.poses):
            self.assertAlmostEqual(pose.pose.position.x, 0.5 * k, places=6)
            self.assertAlmostEqual(pose.pose.position.y, -0.25 * k, places=6)
        self.assertTrue(self.wait_for(lambda: (self.status_of('odometry_path') or self.status_of('path')) is not None
                                      and (self.status_of('path') or {}).get('odometry rejected') == '1'),
                        'the NaN pose is not reported on /diagnostics: %s' % self.statuses.keys())

    def test_registration_knobs(self):
        client = Client('/registration', timeout=20)
        start = client.get_configuration(timeout=10)
        self.assertEqual(start['method'], 'auto')  # from config/registration/pal_survey.yaml
        result = client.update_configuration({'method': 'rmr', 'model': 'affine', 'klt_max_features': 90})
        self.assertEqual(result['method'], 'rmr')
        self.assertEqual(result['model'], 'affine')
        self.assertTrue(self.wait_for(lambda: (self.status_of('registration: registration') or {}).get('method') == 'rmr'
                                      and self.status_of('registration: registration').get('model') == 'affine'),
                        'diagnostics do not show the new method: %s' % self.statuses)
        self.assertEqual(self.status_of('registration: registration').get('reconfigurations'), '1')
        # A value its range allows but the configuration refuses (fewer features than ~klt/min_features = 20) is
        # refused, and the settings in force stay.
        result = client.update_configuration({'klt_max_features': 10})
        self.assertEqual(result['klt_max_features'], 90)
        self.assertEqual(result['method'], 'rmr')

    def test_fusion_gate(self):
        client = Client('/fusion', timeout=20)
        self.assertAlmostEqual(client.get_configuration(timeout=10)['gate_probability'], 0.999, places=9)
        result = client.update_configuration({'gate_probability': 0.999999, 'recovery_rejections': 3})
        self.assertAlmostEqual(result['gate_probability'], 0.999999, places=9)
        self.assertTrue(self.wait_for(lambda: '27.6' in (self.status_of('fusion: fusion') or {}).get('gate', '')),
                        'diagnostics do not show the new gate: %s' % self.status_of('fusion'))


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'operator_knobs', OperatorKnobsTest)
