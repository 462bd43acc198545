#!/usr/bin/env python3
"""Feeds tile_writer_node (~exit_when_idle_s 1.5) synthetic frames, then, with no more images, graph corrections every
0.5 s for 4 s: the writer must still be running (no run_summary.json) while they come, though the images stopped more
than 1.5 s before, and must write run_summary.json and exit within a few seconds after the last one."""
import os
import time
import unittest

import rospy
import rostest
from exocet_msgs.msg import ImageMotion, PositionCorrections
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, Range

from tile_writer_node_check import publish_frames, wait_for_subscribers

FOLDER = os.path.join(os.environ.get('ROS_HOME', '/tmp'), 'test_tile_writer_idle_exit')


class TileWriterIdleExitTest(unittest.TestCase):

    def test_graph_corrections_keep_the_writer_until_they_stop(self):
        rospy.init_node('tile_writer_idle_exit_check')
        summary = os.path.join(FOLDER, 'run_summary.json')
        images = rospy.Publisher('/camera/image_raw', Image, queue_size=100)
        motions = rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=100)
        odometry = rospy.Publisher('/mosaic/odometry', Odometry, queue_size=100)
        heights = rospy.Publisher('/mosaic/camera_height', Range, queue_size=100)
        corrections = rospy.Publisher('/mosaic/graph_corrections', PositionCorrections, queue_size=10)
        self.assertTrue(wait_for_subscribers([images, motions, odometry, corrections]), 'tile writer subscribed')
        if os.path.exists(summary):  # left by an earlier run in the same ROS_HOME
            os.remove(summary)
        start = rospy.Time(1000.0)
        frames = 20
        publish_frames({'images': images, 'motions': motions, 'odometry': odometry, 'heights': heights}, frames,
                       start)
        images_end = time.time()
        # The graph goes on closing loops for 4 s: a correction every 0.5 s, each a little different.
        last = images_end
        for k in range(8):
            time.sleep(0.5)
            self.assertFalse(os.path.exists(summary),
                             'the writer exited %.1f s after the last image while the graph still corrected it'
                             % (time.time() - images_end))
            msg = PositionCorrections()
            msg.header.frame_id = 'utm'
            msg.stamps = [start, start + rospy.Duration(0.2 * frames)]
            msg.east_m, msg.north_m = [0.001 * (k + 1)] * 2, [0.0] * 2
            msg.header.stamp = msg.stamps[-1]
            corrections.publish(msg)
            last = time.time()
        self.assertGreater(last - images_end, 3.5)
        # Quiet now: it flushes and exits after exit_when_idle_s (plus writing its last tile).
        deadline = last + 15.0
        while time.time() < deadline and not os.path.exists(summary):
            time.sleep(0.1)
        self.assertTrue(os.path.exists(summary), 'run_summary.json written once the corrections stopped')
        waited = time.time() - last
        self.assertGreaterEqual(waited, 1.4, 'not before exit_when_idle_s after the last correction')


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_idle_exit', TileWriterIdleExitTest)
