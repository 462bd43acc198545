#!/usr/bin/env python3
"""Feeds tile_writer_node synthetic frames (a textured seabed seen by a nadir camera moving east) with bad input
mixed in, and checks its diagnostics and its behaviour when the output folder cannot be written."""
import time
import unittest

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import ImageMotion
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CompressedImage, Image, Range
from std_srvs.srv import Trigger

WIDTH, HEIGHT, FOCAL_PX, HEIGHT_M = 320, 240, 300.0, 2.0
GSD_M = HEIGHT_M / FOCAL_PX
STEP_PX = 12


def seabed(seed=3):
    rng = np.random.default_rng(seed)
    big = rng.random((HEIGHT + 40, 4000)).astype(np.float32)
    # Smooth it a little (box filter by cumulative sums) so that it looks like texture, not noise.
    k = 5
    c = np.cumsum(np.cumsum(np.pad(big, ((k, 0), (k, 0))), 0), 1)
    smooth = (c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]) / (k * k)
    return (255 * (smooth - smooth.min()) / np.ptp(smooth)).astype(np.uint8)


def wait_for_subscribers(publishers, timeout_s=20.0):
    """Waits (at most timeout_s) until every publisher has a subscriber; True when they all have."""
    deadline = time.time() + timeout_s
    while time.time() < deadline and any(p.get_num_connections() == 0 for p in publishers):
        time.sleep(0.1)
    return all(p.get_num_connections() > 0 for p in publishers)


def chain_publishers(queue_size=200):
    """The tile writer's inputs, as publish_frames takes them: images (raw and compressed), motions, fused poses and
    camera heights on the chain's topics."""
    return {
        'images': rospy.Publisher('/camera/image_raw', Image, queue_size=queue_size),
        'compressed': rospy.Publisher('/camera/image_raw/compressed', CompressedImage, queue_size=10),
        'motions': rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=queue_size),
        'odometry': rospy.Publisher('/mosaic/odometry', Odometry, queue_size=queue_size),
        'heights': rospy.Publisher('/mosaic/camera_height', Range, queue_size=queue_size),
    }


def flush_tile_writer(timeout_s):
    """Calls /tile_writer/flush until it succeeds (every closed mosaic on disk), at most timeout_s; the last reply."""
    rospy.wait_for_service('/tile_writer/flush', timeout=10.0)
    deadline = time.time() + timeout_s
    reply = None
    while time.time() < deadline:
        reply = rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        if reply.success:
            break
        time.sleep(1.0)
    return reply


def publish_frames(publishers, count, start, bad_pose_at=None, bad_image_at=None, first=0):
    """Publishes `count` frames of a nadir camera moving east over seabed(), 0.2 s apart from `start`: the image, its
    motion from the previous one, the fused pose (NaN at bad_pose_at) and the camera height; at bad_image_at a corrupt
    JPEG on the compressed stream. publishers: dict of images, compressed, motions, odometry, heights. `first`: the
    frame to start at, to go on from an earlier call (stamps, place and motion carry on)."""
    texture = seabed()
    previous = start - rospy.Duration(0.2) if first > 0 else None
    for i in range(first, first + count):
        stamp = start + rospy.Duration(0.2 * (i - first))
        image = Image()
        image.header.stamp = stamp
        image.header.frame_id = 'camera_optical'
        image.height, image.width, image.encoding, image.step = HEIGHT, WIDTH, 'mono8', WIDTH
        image.data = texture[20:20 + HEIGHT, i * STEP_PX:i * STEP_PX + WIDTH].tobytes()
        publishers['images'].publish(image)
        if previous is not None:
            motion = ImageMotion()
            motion.header.stamp = stamp
            motion.previous_stamp = previous
            motion.method, motion.model = 'klt', 'translation'
            # The camera moves east (image x right = east with the nadir pose below): the seabed moves left.
            motion.matrix = [1, 0, -STEP_PX, 0, 1, 0, 0, 0, 1]
            motion.camera_matrix = [FOCAL_PX, 0, WIDTH / 2.0, 0, FOCAL_PX, HEIGHT / 2.0, 0, 0, 1]
            motion.parameters, motion.covariance = [-STEP_PX, 0.0], [0.01, 0, 0, 0.01]
            publishers['motions'].publish(motion)
        pose = Odometry()
        pose.header.stamp = stamp
        pose.header.frame_id = 'utm'
        pose.pose.pose.position.x = 500000.0 + i * STEP_PX * GSD_M
        pose.pose.pose.position.y = 4700000.0
        # Nadir camera, image top = north: x_cam = east, y_cam = south, z_cam = down (a rotation of pi about x).
        pose.pose.pose.orientation.x, pose.pose.pose.orientation.w = 1.0, 0.0
        pose.pose.covariance[0] = pose.pose.covariance[7] = 0.01
        if i == bad_pose_at:
            pose.pose.pose.position.x = float('nan')  # bad input: rejected, counted
        publishers['odometry'].publish(pose)
        height = Range()
        height.header.stamp = stamp
        height.range = HEIGHT_M
        publishers['heights'].publish(height)
        previous = stamp
        if i == bad_image_at:
            bad = CompressedImage()
            bad.header.stamp = stamp + rospy.Duration(0.1)
            bad.format = 'jpeg'
            bad.data = b'not a jpeg at all'
            publishers['compressed'].publish(bad)  # ignored: the node listens to the raw stream it received first
        time.sleep(0.02)


class TileWriterNodeTest(unittest.TestCase):

    def test_bad_input_and_unwritable_folder(self):
        rospy.init_node('tile_writer_node_check')
        statuses = []

        def on_diagnostics(msg):
            statuses.extend(s for s in msg.status if 'tile' in s.name)
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        images = rospy.Publisher('/camera/image_raw', Image, queue_size=100)
        compressed = rospy.Publisher('/camera/image_raw/compressed', CompressedImage, queue_size=100)
        motions = rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=100)
        odometry = rospy.Publisher('/mosaic/odometry', Odometry, queue_size=100)
        heights = rospy.Publisher('/mosaic/camera_height', Range, queue_size=100)
        deadline = time.time() + 20.0
        while time.time() < deadline and (images.get_num_connections() == 0 or motions.get_num_connections() == 0
                                          or odometry.get_num_connections() == 0):
            time.sleep(0.1)
        publish_frames({'images': images, 'compressed': compressed, 'motions': motions, 'odometry': odometry,
                        'heights': heights}, 40, rospy.Time(1000.0), bad_pose_at=7, bad_image_at=5)
        time.sleep(1.0)
        rospy.wait_for_service('/tile_writer/flush', timeout=10.0)
        reply = rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        self.assertFalse(reply.success, 'the folder cannot be written: the flush says so')
        self.assertIn('exocet_cannot_write_here', reply.message)
        # The node keeps running and reports the failed write and the rejected pose on /diagnostics.
        deadline = time.time() + 10.0
        found = None
        while time.time() < deadline and found is None:
            for s in list(statuses):
                values = {kv.key: kv.value for kv in s.values}
                if s.level == 2 and int(values.get('tiles waiting for a retry', 0)) >= 1:
                    found = (s, values)
            time.sleep(0.2)
        self.assertIsNotNone(found, 'an ERROR on /diagnostics with the tile kept for a retry')
        status, values = found
        self.assertIn('exocet_cannot_write_here', status.message + values.get('last write error', ''))
        self.assertGreaterEqual(int(values['images rejected']), 1, 'the NaN pose is counted')
        self.assertEqual(int(values['images received']), 40)
        # Key frames: the camera moves 5% of the image per frame, a key frame every 10%: about half are blended.
        self.assertGreaterEqual(int(values['frames composed']), 12)
        self.assertEqual(int(values['tiles lost']), 0, 'nothing is lost while it is retried')
        # What the heap holds (make soak fits its slope): the open mosaic and the tile kept for a retry, in MB.
        self.assertTrue(1.0 < float(values['heap in use (MB)']) < 4096.0, values['heap in use (MB)'])
        self.assertGreaterEqual(float(values['heap freed, kept by malloc (MB)']), 0.0)
        # The node runs on jemalloc (exocet_long_running_allocator), found at run time.
        self.assertEqual(values.get('heap allocator'), 'jemalloc')


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_node', TileWriterNodeTest)
