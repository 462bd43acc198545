#!/usr/bin/env python3
"""Checks what rviz shows during a replay (run by rviz_replay.test).

rviz runs launch/exocet.rviz on a virtual display. The checker waits until rviz watches the decoded camera images
(display_image_node decodes only for a subscriber), plays the bag, and takes a screenshot after the first tile and
one at the end. In each: the 3D view's background is there, the fused path (green) and the vehicle's axes (red, at the
view's centre: the view follows the vehicle) are drawn in it, and the left dock shows two images (the mosaic preview
and the camera: two runs of rows in seabed colours rather than the panels' greys). The fused path must be longer in the second.
"""
import atexit
import os
import signal
import subprocess
import time
import unittest

import cv2
import numpy as np
import rosgraph
import rospy
import rostest
from exocet_msgs.msg import Tile as TileMsg
from nav_msgs.msg import Odometry

BACKGROUND_BGR = (60, 40, 30)  # exocet.rviz's background colour 30; 40; 60 (RGB)


def subscribers_of(topic):
    state = rosgraph.Master('/check_rviz_replay').getSystemState()
    for name, nodes in state[1]:
        if name == topic:
            return nodes
    return []


def screenshot(display, path):
    subprocess.run(['import', '-display', display, '-window', 'root', path], check=True, timeout=30)
    image = cv2.imread(path, cv2.IMREAD_COLOR)
    if image is None:
        raise AssertionError('screenshot %s not readable' % path)
    return image


def measure(image):
    """What the checks look at in a screenshot (BGR)."""
    b, g, r = [image[:, :, k].astype(int) for k in range(3)]
    background = (abs(b - BACKGROUND_BGR[0]) <= 3) & (abs(g - BACKGROUND_BGR[1]) <= 3) & (abs(r - BACKGROUND_BGR[2]) <= 3)
    ys, xs = np.nonzero(background)
    view = (xs.min(), ys.min(), xs.max(), ys.max()) if len(xs) else None
    out = {'background_fraction': background.mean(), 'view': view}
    if view is None:
        return out
    x0, y0, x1, y1 = view
    inside = np.zeros(background.shape, bool)
    inside[y0:y1 + 1, x0:x1 + 1] = True
    out['green_px'] = int(((g > 200) & (r < 90) & (b < 90) & inside).sum())
    red = (r > 200) & (g < 60) & (b < 60) & inside
    out['red_px'] = int(red.sum())
    if out['red_px']:
        ry, rx = np.nonzero(red)
        cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
        out['red_from_centre_px'] = float(np.hypot(rx.mean() - cx, ry.mean() - cy))
    # The dock left of the view: images of the seabed are coloured; Qt's panels are grey.
    dock = cv2.cvtColor(image[:, :max(1, x0 - 5)], cv2.COLOR_BGR2HSV)
    coloured = (dock[:, :, 1] > 25) & (dock[:, :, 2] > 40)
    out['dock_image_fraction'] = float(coloured.mean())
    # Each image is a run of rows that are mostly seabed: the mosaic preview, then the camera.
    rows = coloured.mean(axis=1) > 0.3
    runs, length = 0, 0
    for r in list(rows) + [False]:
        if r:
            length += 1
        else:
            runs += 1 if length >= 40 else 0
            length = 0
    out['dock_images'] = runs
    return out


class RvizReplayTest(unittest.TestCase):

    def test_rviz_shows_the_dive(self):
        rospy.init_node('check_rviz_replay')
        bag = rospy.get_param('~bag')
        display = rospy.get_param('~display')
        shots = rospy.get_param('~screenshot_dir')
        os.makedirs(shots, exist_ok=True)
        tiles, poses = [], []
        rospy.Subscriber('/mosaic/tile', TileMsg, tiles.append, queue_size=50)
        rospy.Subscriber('/mosaic/odometry', Odometry, poses.append, queue_size=1000)
        start = time.time()
        while time.time() - start < 90.0 and not any('rviz' in n for n in subscribers_of('/camera/image_display')):
            time.sleep(0.5)
        self.assertTrue(any('rviz' in n for n in subscribers_of('/camera/image_display')),
                        'rviz does not watch /camera/image_display (did it start on %s?)' % display)
        topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
                  '/nav/altitude', '/nav/datum', '/tf_static', '/ground_truth/odometry']
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics'] + topics,
                                  start_new_session=True)
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        start = time.time()
        while time.time() - start < 180.0 and not tiles:
            time.sleep(0.5)
        self.assertTrue(tiles, 'no tile written')
        time.sleep(3.0)  # rviz draws at 20 frames/s; the preview comes every 0.5 s
        first = measure(screenshot(display, os.path.join(shots, 'rviz_replay_1.png')))
        start = time.time()
        while time.time() - start < 180.0 and player.poll() is None:
            time.sleep(0.5)
        time.sleep(3.0)
        second = measure(screenshot(display, os.path.join(shots, 'rviz_replay_2.png')))
        rospy.loginfo('rviz_replay: first %s; second %s', first, second)
        for name, m in (('first', first), ('second', second)):
            self.assertIsNotNone(m['view'], '%s screenshot: no 3D view (background colour) at all' % name)
            self.assertGreater(m['background_fraction'], 0.2, '%s screenshot: the 3D view is mostly covered' % name)
            self.assertGreater(m['green_px'], 150, '%s screenshot: the fused path is not drawn' % name)
            self.assertGreater(m['red_px'], 20, '%s screenshot: the vehicle (axes) is not drawn' % name)
            self.assertLess(m['red_from_centre_px'], 80, '%s screenshot: the view does not follow the vehicle' % name)
            self.assertGreaterEqual(m['dock_images'], 2,
                                    '%s screenshot: the camera image and the mosaic preview are not both shown' % name)
        self.assertGreater(second['green_px'], first['green_px'], 'the fused path did not grow')


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'rviz_replay', RvizReplayTest)
