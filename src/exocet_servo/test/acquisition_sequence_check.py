#!/usr/bin/env python3
"""Checks the acquisition sequence (run by acquisition_sequence.test): the sequencer's bag holds one stereo pair and
the arm pose per stop, and the stops follow the rig-induced trajectory (left camera at stop k + 1 = right camera at
stop k)."""
import math
import time
import unittest

import numpy as np
import rosbag
import rospy
import rostest
from std_msgs.msg import String

PKG = 'exocet_servo'


def rotation(q):
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


class AcquisitionSequence(unittest.TestCase):
    def test_stops_follow_the_rig_transform(self):
        status = {'text': None}
        rospy.Subscriber('/acquisition_sequencer/status', String, lambda m: status.update(text=m.data))
        deadline = time.time() + 450.0
        while time.time() < deadline and not rospy.is_shutdown():
            if status['text'] and (status['text'].startswith('done') or status['text'].startswith('failed')):
                break
            time.sleep(0.2)
        self.assertIsNotNone(status['text'])
        self.assertTrue(status['text'].startswith('done'), status['text'])
        stops = {}
        with rosbag.Bag(rospy.get_param('~bag')) as bag:
            for topic, msg, t in bag.read_messages():
                stops.setdefault(t.to_nsec(), {})[topic] = msg
        self.assertEqual(len(stops), 3)
        ordered = [stops[k] for k in sorted(stops)]
        for s in ordered:
            for topic in ('left/image_raw', 'right/image_raw', 'left/camera_info', 'right/camera_info',
                          'joint_states', 'left/pose', 'right/pose'):
                self.assertIn(topic, s)
            self.assertEqual(s['left/image_raw'].width, 640)
            self.assertEqual(len(s['joint_states'].position), 6)
        for k in range(len(ordered) - 1):
            right = ordered[k]['right/pose'].pose
            left = ordered[k + 1]['left/pose'].pose
            p = lambda pose: np.array([pose.position.x, pose.position.y, pose.position.z])
            position_mm = 1000.0 * np.linalg.norm(p(left) - p(right))
            cos = (np.trace(rotation(right.orientation).T @ rotation(left.orientation)) - 1.0) / 2.0
            rotation_deg = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
            step_mm = 1000.0 * np.linalg.norm(p(left) - p(ordered[k]['left/pose'].pose))
            rospy.loginfo('stop %d -> %d: left camera moved %.1f mm; %.3f mm, %.4f deg from where the right one was',
                          k + 1, k + 2, step_mm, position_mm, rotation_deg)
            self.assertGreater(step_mm, 250.0)
            self.assertLess(position_mm, 2.0)
            self.assertLess(rotation_deg, 0.2)


if __name__ == '__main__':
    rospy.init_node('acquisition_sequence_check')
    rostest.rosrun(PKG, 'acquisition_sequence', AcquisitionSequence)
