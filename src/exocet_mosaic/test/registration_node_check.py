#!/usr/bin/env python3
"""Drives registration_node with known images and bad input (run by registration_node.test)."""
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import ImageMotion
from sensor_msgs.msg import Image

PKG = 'exocet_mosaic'
WIDTH, HEIGHT = 320, 240
SHIFT = (3, 2)  # the camera's window moves by this much (pixels) per frame: the content moves by minus this


def texture(size=(700, 900), seed=5):
    """Smooth random texture, 8-bit: white noise box-filtered twice (cumulative sums)."""
    rng = np.random.default_rng(seed)
    t = rng.random(size)
    for _ in range(2):
        for axis in (0, 1):
            c = np.cumsum(t, axis=axis)
            r = 3
            t = (np.roll(c, -r, axis=axis) - np.roll(c, r, axis=axis)) / (2 * r)
    t = t[20:-20, 20:-20]
    t = (t - t.min()) / (t.max() - t.min())
    return (40 + 180 * t).astype(np.uint8)


TEXTURE = texture()


def view(i, width=WIDTH, height=HEIGHT):
    x0, y0 = 10 + SHIFT[0] * i, 10 + SHIFT[1] * i
    return TEXTURE[y0:y0 + height, x0:x0 + width].copy()


def image_msg(gray, stamp_s, encoding='mono8'):
    msg = Image()
    msg.header.stamp = rospy.Time.from_sec(stamp_s)
    msg.header.frame_id = 'camera_optical'
    msg.height, msg.width = gray.shape[:2]
    msg.encoding = encoding
    if encoding == 'mono8' or encoding.startswith('bayer_'):
        data, step = gray, gray.shape[1]
    elif encoding == 'mono16':
        data = gray.astype('>u2' if msg.is_bigendian else '<u2') * 256
        step = 2 * gray.shape[1]
    elif encoding in ('bgr8', 'rgb8'):
        data, step = np.dstack([gray, gray, gray]), 3 * gray.shape[1]
    else:
        raise ValueError(encoding)
    msg.step = step
    msg.data = data.tobytes()
    return msg


class RegistrationNodeTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('registration_node_check')
        cls.motions = []
        cls.diagnostics = []
        rospy.Subscriber('/mosaic/motion', ImageMotion, cls.motions.append, queue_size=100)
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=100)
        cls.pub = rospy.Publisher('/camera/image_raw', Image, queue_size=100)
        deadline = time.time() + 30
        while cls.pub.get_num_connections() == 0:
            if time.time() > deadline:
                raise RuntimeError('registration_node did not subscribe to /camera/image_raw')
            time.sleep(0.1)
        time.sleep(0.5)

    def send(self, msg, expect_motion):
        """Publishes one image; returns its motion message, or None after checking that none came."""
        before = len(self.motions)
        self.pub.publish(msg)
        deadline = time.time() + (10.0 if expect_motion else 1.5)
        while time.time() < deadline and len(self.motions) == before:
            time.sleep(0.02)
        if expect_motion:
            self.assertEqual(len(self.motions), before + 1, 'one motion for image stamped %.3f' %
                             msg.header.stamp.to_sec())
            m = self.motions[-1]
            self.assertEqual(m.header.stamp, msg.header.stamp)
            return m
        self.assertEqual(len(self.motions), before, 'no motion expected for image stamped %.3f (%s)' %
                         (msg.header.stamp.to_sec(), msg.encoding))
        return None

    def assertShift(self, m, shift=SHIFT):
        self.assertFalse(m.failed, '%s: %s' % (m.failure, m.failure_detail))
        h = np.array(m.matrix).reshape(3, 3)
        for x, y in ((0.0, 0.0), (m.image_width - 1.0, m.image_height - 1.0)):
            p = h @ np.array([x, y, 1.0])
            self.assertAlmostEqual(p[0] / p[2] - x, -shift[0], delta=0.1)
            self.assertAlmostEqual(p[1] / p[2] - y, -shift[1], delta=0.1)
        self.assertEqual(len(m.covariance), len(m.parameters) ** 2)
        self.assertGreater(m.covariance[0], 0.0)

    def test_sequence_with_bad_input(self):
        # No camera_info is ever published: the first ~camera_info_wait_s (3 s) of images are held back, then
        # registered when the wait runs out, before the image that ends it.
        held_stamps = (997.0, 997.1, 997.2)
        for j, held_stamp in enumerate(held_stamps):
            self.assertIsNone(self.send(image_msg(view(j), held_stamp), False))
        before = len(self.motions)
        t, i = 1000.0, 0
        self.pub.publish(image_msg(view(i), t))  # 2.8 s after the last held one: a gap, the sequence restarts
        deadline = time.time() + 10.0
        while time.time() < deadline and len(self.motions) < before + 2:
            time.sleep(0.02)
        time.sleep(1.0)
        self.assertEqual([round(m.header.stamp.to_sec(), 6) for m in self.motions[before:]], list(held_stamps[1:]))
        for m in self.motions[before:]:
            self.assertShift(m)
        for encoding in ('mono8', 'mono8', 'bgr8', 'rgb8', 'mono16', 'mono16', 'bayer_rggb8', 'bayer_rggb8', 'mono8'):
            t, i = t + 0.1, i + 1
            m = self.send(image_msg(view(i), t, encoding), True)
            self.assertShift(m)
            self.assertAlmostEqual(m.previous_stamp.to_sec(), t - 0.1, places=6)

        # Corrupt data (shorter than step x height) and an unsupported encoding: skipped, the sequence goes on.
        bad = image_msg(view(i + 1), t + 0.1)
        bad.data = bad.data[:len(bad.data) // 2]
        self.send(bad, False)
        float_image = image_msg(view(i + 1), t + 0.1)
        float_image.encoding = '32FC1'
        float_image.step = 4 * WIDTH
        float_image.data = np.zeros((HEIGHT, WIDTH), np.float32).tobytes()
        self.send(float_image, False)
        # A dropped frame: the next image is two shifts away, and still registered.
        t, i = t + 0.2, i + 2
        self.assertShift(self.send(image_msg(view(i), t), True), (2 * SHIFT[0], 2 * SHIFT[1]))

        # Another size: the sequence restarts (no motion), then goes on at the new size.
        t, i = t + 0.1, i + 1
        self.send(image_msg(view(i, 200, 160), t), False)
        t, i = t + 0.1, i + 1
        m = self.send(image_msg(view(i, 200, 160), t), True)
        self.assertShift(m)
        self.assertEqual((m.image_width, m.image_height), (200, 160))

        # Stamps going back (a bag replayed again): restart.
        t, i = t - 50.0, i + 1
        self.send(image_msg(view(i), t), False)
        t, i = t + 0.1, i + 1
        self.assertShift(self.send(image_msg(view(i), t), True))

        # A gap longer than ~max_gap_s: restart.
        t, i = t + 5.0, i + 1
        self.send(image_msg(view(i), t), False)
        t, i = t + 0.1, i + 1
        self.assertShift(self.send(image_msg(view(i), t), True))

        # A blank image: a failure, reported as such.
        t = t + 0.1
        m = self.send(image_msg(np.full((HEIGHT, WIDTH), 128, np.uint8), t), True)
        self.assertTrue(m.failed)
        self.assertIn(m.failure, ('too_little_texture', 'too_dark', 'too_few_tracks', 'too_few_inliers'))
        self.assertEqual(m.matrix[0], 1.0)

        # /diagnostics: the counts of what happened.
        deadline = time.time() + 5.0
        values = {}
        while time.time() < deadline:
            for array in reversed(self.diagnostics):
                for status in array.status:
                    if status.name.endswith('registration'):
                        values = {kv.key: kv.value for kv in status.values}
                        break
                if values.get('pairs failed') == '1':
                    break
            if values.get('pairs failed') == '1':
                break
            time.sleep(0.2)
        self.assertEqual(values.get('images rejected'), '2', values)
        self.assertEqual(values.get('images held back for camera_info'), '3', values)
        self.assertEqual(values.get('sequence restarts'), '4', values)
        self.assertEqual(values.get('pairs failed'), '1', values)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'registration_node', RegistrationNodeTest)
