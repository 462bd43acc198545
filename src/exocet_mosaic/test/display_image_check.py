#!/usr/bin/env python3
"""Checks display_image_node (run by display_image.test): lazy subscription, scaling, a corrupt image survived."""
import time
import unittest

import cv2
import numpy as np
import rosgraph
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import CompressedImage, Image

CAMERA = '/test_camera/image_raw/compressed'


def subscribers_of(topic):
    for name, nodes in rosgraph.Master('/display_image_check').getSystemState()[1]:
        if name == topic:
            return nodes
    return []


def wait_for(predicate, timeout_s=10.0):
    end = time.time() + timeout_s
    while time.time() < end:
        if predicate():
            return True
        time.sleep(0.05)
    return False


class DisplayImageTest(unittest.TestCase):

    def test_decodes_only_while_watched(self):
        rospy.init_node('display_image_check')
        statuses = {}
        rospy.Subscriber('/diagnostics', DiagnosticArray,
                         lambda m: statuses.update({s.name: {v.key: v.value for v in s.values} for s in m.status}))
        camera = rospy.Publisher(CAMERA, CompressedImage, queue_size=10)
        time.sleep(2.0)
        self.assertFalse(any('display_image' in n for n in subscribers_of(CAMERA)),
                         'the camera is read while nobody watches')
        shown = []
        watcher = rospy.Subscriber('/camera/image_display', Image, shown.append, queue_size=10)
        self.assertTrue(wait_for(lambda: any('display_image' in n for n in subscribers_of(CAMERA))),
                        'a display came and the camera is not read: %s; display watched by %s' % (subscribers_of(CAMERA), subscribers_of('/camera/image_display')))
        self.assertTrue(wait_for(lambda: camera.get_num_connections() > 0))
        image = np.zeros((480, 640, 3), np.uint8)
        image[:, :320] = (0, 0, 255)
        msg = CompressedImage(format='bgr8; jpeg compressed bgr8', data=cv2.imencode('.jpg', image)[1].tobytes())
        bad = CompressedImage(format='jpeg', data=b'\xff\xd8 not a jpeg')
        for k in range(5):
            camera.publish(bad if k == 2 else msg)
            time.sleep(0.1)
        self.assertTrue(wait_for(lambda: len(shown) >= 3), 'decoded images not published: %d' % len(shown))
        self.assertEqual((shown[0].width, shown[0].height, shown[0].encoding), (320, 240, 'bgr8'))
        self.assertTrue(wait_for(lambda: any(s.get('images that could not be decoded') == '1'
                                             for s in statuses.values())), 'the corrupt JPEG is not reported')
        watcher.unregister()
        self.assertTrue(wait_for(lambda: not any('display_image' in n for n in subscribers_of(CAMERA))),
                        'the camera is still read after the display went')


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'display_image', DisplayImageTest)
