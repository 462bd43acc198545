#!/usr/bin/env python3
"""Checks the closed loop between arm_rig_simulator_node and servo_node (run by servo_closed_loop.test).

The right camera's pose (tf) when the reference is captured is where the left camera must arrive; the servo reports
how it ended on ~status. The left camera's final pose is compared with that target.
"""
import math
import time
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from std_msgs.msg import String
from std_srvs.srv import Trigger

PKG = 'exocet_servo'
WORLD, LEFT, RIGHT = 'arm_base', 'left_camera_optical', 'right_camera_optical'


def pose_of(buffer, frame):
    t = buffer.lookup_transform(WORLD, frame, rospy.Time(0), rospy.Duration(5.0)).transform
    q = t.rotation
    x, y, z, w = q.x, q.y, q.z, q.w
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return np.array([t.translation.x, t.translation.y, t.translation.z]), rot


class ServoClosedLoop(unittest.TestCase):
    def setUp(self):
        self.status = None
        rospy.Subscriber('/servo/status', String, self.on_status)
        self.buffer = tf2_ros.Buffer()
        self.listener = tf2_ros.TransformListener(self.buffer)

    def on_status(self, msg):
        self.status = msg.data

    def wait_status(self, predicate, timeout_s):
        deadline = time.time() + timeout_s
        while time.time() < deadline and not rospy.is_shutdown():
            if self.status is not None and predicate(self.status):
                return self.status
            time.sleep(0.1)
        return self.status

    def test_left_camera_reaches_the_right_cameras_pose(self):
        rospy.wait_for_service('/servo/capture_reference', 60.0)
        capture = rospy.ServiceProxy('/servo/capture_reference', Trigger)
        # The simulator needs a first image pair; the servo refuses a capture until it has one.
        deadline = time.time() + 60.0
        answer = capture()
        while not answer.success and time.time() < deadline:
            time.sleep(0.5)
            answer = capture()
        self.assertTrue(answer.success, answer.message)
        target_p, target_r = pose_of(self.buffer, RIGHT)
        start_p, _ = pose_of(self.buffer, LEFT)
        # The latched status may still say 'idle' until the servo's first iteration: wait past both.
        status = self.wait_status(lambda s: s not in ('servoing', 'idle'), 300.0)
        self.assertIsNotNone(status)
        self.assertTrue(status.startswith('converged'), status)
        time.sleep(1.0)  # the last tf
        final_p, final_r = pose_of(self.buffer, LEFT)
        position_mm = 1000.0 * np.linalg.norm(final_p - target_p)
        cos = (np.trace(target_r.T @ final_r) - 1.0) / 2.0
        rotation_deg = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
        rospy.loginfo('servo closed loop: start %.1f mm from the target; final %.3f mm, %.4f deg; %s',
                      1000.0 * np.linalg.norm(start_p - target_p), position_mm, rotation_deg, status)
        self.assertLess(position_mm, 2.0)
        self.assertLess(rotation_deg, 0.2)


if __name__ == '__main__':
    rospy.init_node('servo_closed_loop_check')
    rostest.rosrun(PKG, 'servo_closed_loop', ServoClosedLoop)
