#!/usr/bin/env python3
"""Checks the servo node's safety stops in closed loop with arm_rig_simulator_node (run by servo_safety_stop.test).

1. Lost tracking: a servoing starts, then the simulator's ~hide_scene leaves both cameras looking at open water; the
   servo must stop with "safety stop: lost tracking", the arm must stand still, /diagnostics must say ERROR.
2. Joint limit: the servo node is given a tight limit on one joint (~safety/joint_min_rad or joint_max_rad, the
   test's ~joint and ~bound say which) that a normal servoing crosses; the servo must stop with "safety stop: joint
   limit" naming that joint and its limit, before the joint passes the limit; the arm must stand still. The node still
   answers: a new ~capture_reference succeeds and that servoing stops on the same limit without passing it.
Every wait is on a status, not a fixed sleep (the test shares 2 cores with others).
"""
import math
import time
import unittest

import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

PKG = 'exocet_servo'
WORLD, LEFT = 'arm_base', 'left_camera_optical'
SERVO_HARDWARE_ID = 'exocet stereo servo'


class ServoSafetyStop(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.statuses = []  # every ~status message: a quick stop must not hide the 'servoing' before it
        cls.joints = None
        cls.diagnostic = None
        rospy.Subscriber('/servo/status', String, cls.on_status)
        rospy.Subscriber('/joint_states', JointState, cls.on_joints)
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.on_diagnostics)
        cls.buffer = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.buffer)
        rospy.wait_for_service('/servo/capture_reference', 60.0)
        cls.capture = rospy.ServiceProxy('/servo/capture_reference', Trigger)

    @classmethod
    def on_status(cls, msg):
        cls.statuses.append(msg.data)

    @classmethod
    def on_joints(cls, msg):
        cls.joints = msg

    @classmethod
    def on_diagnostics(cls, msg):
        for status in msg.status:
            if status.hardware_id == SERVO_HARDWARE_ID:
                cls.diagnostic = status

    def wait_for(self, predicate, timeout_s):
        deadline = time.time() + timeout_s
        while time.time() < deadline and not rospy.is_shutdown():
            if predicate():
                return True
            time.sleep(0.05)
        return predicate()

    def start_servoing(self):
        """Captures a reference (retried: the first images, or a view of open water, are refused)."""
        deadline = time.time() + 60.0
        first = len(self.statuses)
        answer = self.capture()
        while not answer.success and time.time() < deadline:
            time.sleep(0.5)
            first = len(self.statuses)
            answer = self.capture()
        self.assertTrue(answer.success, answer.message)
        self.assertTrue(self.wait_for(lambda: 'servoing' in self.statuses[first:], 5.0), self.statuses[first:])
        self.servoing_at = first + self.statuses[first:].index('servoing')

    def wait_end(self, timeout_s):
        """The status that ended the servoing started by start_servoing()."""
        self.assertTrue(self.wait_for(lambda: len(self.statuses) > self.servoing_at + 1, timeout_s),
                        'still servoing after %.0f s' % timeout_s)
        return self.statuses[self.servoing_at + 1]

    def joint_state_after(self, stamp):
        """The first joint state stamped after `stamp` (the simulator publishes one per tick)."""
        self.assertTrue(self.wait_for(lambda: self.joints is not None and self.joints.header.stamp > stamp, 10.0),
                        'no joint state after the stop')
        return self.joints

    def left_position(self):
        t = self.buffer.lookup_transform(WORLD, LEFT, rospy.Time(0), rospy.Duration(5.0)).transform.translation
        return (t.x, t.y, t.z)

    def assert_arm_stands_still(self):
        """Two ticks after the stop (the zero velocity applied), then over two more ticks: no joint moves."""
        first = self.joint_state_after(rospy.Time.now() + rospy.Duration(0.3))
        p0 = self.left_position()
        last = self.joint_state_after(first.header.stamp + rospy.Duration(0.3))
        p1 = self.left_position()
        self.assertLess(max(abs(v) for v in last.velocity), 1e-9, 'joint velocities %s' % (list(last.velocity),))
        moved_rad = max(abs(a - b) for a, b in zip(first.position, last.position))
        self.assertLess(moved_rad, 1e-9, 'joints moved %.3g rad after the stop' % moved_rad)
        moved_mm = 1000.0 * math.dist(p0, p1)
        self.assertLess(moved_mm, 1e-3, 'left camera moved %.3g mm after the stop' % moved_mm)
        return last

    def assert_diagnostics_error(self, words):
        ok = self.wait_for(lambda: self.diagnostic is not None and self.diagnostic.level == DiagnosticStatus.ERROR and
                           words in self.diagnostic.message, 5.0)
        self.assertTrue(ok, 'diagnostics: %s' % (self.diagnostic,))

    def test_1_lost_tracking_stops_the_arm(self):
        start = time.time()
        self.start_servoing()
        rospy.set_param('/arm_rig_simulator/hide_scene', True)
        try:
            status = self.wait_end(40.0)
            rospy.loginfo('safety stop check (lost tracking): %s (%.1f s)', status, time.time() - start)
            self.assertTrue(status.startswith('safety stop: lost tracking'), status)
            self.assert_arm_stands_still()
            self.assert_diagnostics_error('lost tracking')
        finally:
            rospy.set_param('/arm_rig_simulator/hide_scene', False)

    def test_2_joint_limit_stops_the_arm(self):
        joint = rospy.get_param('~joint')
        bound = rospy.get_param('~bound')  # 'upper' or 'lower'
        names = rospy.get_param('/servo/safety/joint_names', ['joint_%d' % (j + 1) for j in range(6)])
        index = names.index(joint)
        limit = rospy.get_param('/servo/safety/joint_%s_rad' % ('max' if bound == 'upper' else 'min'))[index]
        beyond = (lambda q: q > limit) if bound == 'upper' else (lambda q: q < limit)
        start = time.time()
        self.start_servoing()
        q_start = self.joints.position[self.joints.name.index(joint)]
        status = self.wait_end(60.0)
        rospy.loginfo('safety stop check (joint limit): %s (%.1f s; %s from %.3f rad, limit %.3f rad)', status,
                      time.time() - start, joint, q_start, limit)
        self.assertTrue(status.startswith('safety stop: joint limit: %s ' % joint), status)
        self.assertIn('%s limit %.3f rad' % (bound, limit), status)
        still = self.assert_arm_stands_still()
        q_stop = still.position[still.name.index(joint)]
        self.assertFalse(beyond(q_stop), '%s at %.4f rad, beyond the limit %.4f rad' % (joint, q_stop, limit))
        self.assertGreater(abs(q_stop - q_start), 0.01, 'the joint hardly moved: the limit was not reached by servoing')
        self.assert_diagnostics_error('joint limit')

        # The node keeps running: a new servoing starts, and stops on the same limit without crossing it.
        self.start_servoing()
        status = self.wait_end(30.0)
        rospy.loginfo('safety stop check (after the stop, a new servoing): %s', status)
        self.assertTrue(status.startswith('safety stop: joint limit: %s ' % joint), status)
        still = self.assert_arm_stands_still()
        q_again = still.position[still.name.index(joint)]
        self.assertFalse(beyond(q_again), '%s at %.4f rad, beyond the limit %.4f rad' % (joint, q_again, limit))


if __name__ == '__main__':
    rospy.init_node('servo_safety_stop_check')
    rostest.rosrun(PKG, 'servo_safety_stop', ServoSafetyStop)
