#!/usr/bin/env python3
"""Feeds tile_writer_node (following the pose graph) synthetic frames of a nadir camera moving east, then graph
corrections that move the whole dive 5 cm east: every written tile is drawn again, as version 2, 5 cm further east,
announced on /mosaic/tile; its first version's file is gone, the new one is there; the folder's virtual mosaic
(tile_mosaic.vrt) names the new versions; /diagnostics counts it."""
import os
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import ImageMotion, PositionCorrections, Tile
from nav_msgs.msg import Odometry
from sensor_msgs.msg import Image, Range

from tile_writer_node_check import publish_frames

MOVE_EAST_M = 0.05


class TileWriterGraphTest(unittest.TestCase):

    def test_tiles_follow_the_graph(self):
        rospy.init_node('tile_writer_graph_check')
        tiles, statuses = [], []
        rospy.Subscriber('/mosaic/tile', Tile, tiles.append, queue_size=100)
        rospy.Subscriber('/diagnostics', DiagnosticArray,
                         lambda msg: statuses.extend(s for s in msg.status if 'tile' in s.name), queue_size=100)
        images = rospy.Publisher('/camera/image_raw', Image, queue_size=100)
        motions = rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=100)
        odometry = rospy.Publisher('/mosaic/odometry', Odometry, queue_size=100)
        heights = rospy.Publisher('/mosaic/camera_height', Range, queue_size=100)
        corrections = rospy.Publisher('/mosaic/graph_corrections', PositionCorrections, queue_size=1, latch=True)
        deadline = time.time() + 20.0
        while time.time() < deadline and (images.get_num_connections() == 0 or motions.get_num_connections() == 0
                                          or odometry.get_num_connections() == 0
                                          or corrections.get_num_connections() == 0):
            time.sleep(0.1)
        start = rospy.Time(1000.0)
        frames = 32
        publish_frames({'images': images, 'motions': motions, 'odometry': odometry, 'heights': heights}, frames,
                       start)
        deadline = time.time() + 20.0
        while time.time() < deadline and len(tiles) < 2:
            time.sleep(0.1)
        first = {t.index: t for t in tiles if t.version == 1}
        self.assertGreaterEqual(len(first), 2, 'tiles written before the graph moves them')

        # Bad input first: stamps and values of different lengths. Refused and counted; nothing is drawn again.
        bad = PositionCorrections()
        bad.header.frame_id = 'utm'
        bad.stamps = [start, start + rospy.Duration(1.0)]
        bad.east_m, bad.north_m = [MOVE_EAST_M], [0.0, 0.0]
        corrections.publish(bad)
        time.sleep(2.0)
        self.assertFalse([t for t in tiles if t.version > 1], 'refused corrections move nothing')
        rejected = 0
        for s in list(statuses):
            values = {kv.key: kv.value for kv in s.values}
            rejected = max(rejected, int(values.get('images rejected', 0)))
            if 'differ in length' in values.get('last problem', ''):
                rejected = max(rejected, 1)
        self.assertGreaterEqual(rejected, 1, 'the refused corrections are counted on /diagnostics')

        # The graph now puts the whole dive 5 cm further east.
        msg = PositionCorrections()
        msg.header.frame_id = 'utm'
        msg.stamps = [start, start + rospy.Duration(0.2 * frames)]
        msg.east_m, msg.north_m = [MOVE_EAST_M] * 2, [0.0] * 2
        # The graph's 1-sigma of the first key frame; none yet for the second (NaN: added after its marginals).
        msg.east_sigma_m, msg.north_sigma_m = [0.02, float('nan')], [0.03, float('nan')]
        msg.east_north_correlation = [-0.25, float('nan')]
        msg.header.stamp = msg.stamps[-1]
        corrections.publish(msg)
        deadline = time.time() + 30.0
        redrawn = {}
        while time.time() < deadline and not all(i in redrawn for i in first):
            redrawn = {t.index: t for t in list(tiles) if t.version == 2}
            time.sleep(0.1)
        for index, old in first.items():
            self.assertIn(index, redrawn, 'tile %d drawn again within 30 s' % index)
            new = redrawn[index]
            self.assertTrue(new.geotiff_path.endswith('_v2.tif'), new.geotiff_path)
            self.assertTrue(os.path.exists(new.geotiff_path), new.geotiff_path)
            self.assertFalse(os.path.exists(old.geotiff_path), 'the first version goes once the second exists')
            # Moved east by the correction, within a pixel (the grid stays on multiples of the GSD).
            self.assertAlmostEqual(new.min_easting_m - old.min_easting_m, MOVE_EAST_M, delta=1.01 * new.gsd_m)
            self.assertAlmostEqual(new.min_northing_m, old.min_northing_m, delta=1.01 * new.gsd_m)
            self.assertEqual(new.first_frame, old.first_frame)
        # The GIS's one layer: the virtual mosaic names the new versions (rewritten at most every 2 s).
        vrt = os.path.join(os.path.dirname(redrawn[min(redrawn)].geotiff_path), 'tile_mosaic.vrt')
        deadline = time.time() + 10.0
        names = []
        while time.time() < deadline:
            text = open(vrt).read() if os.path.exists(vrt) else ''
            names = [os.path.basename(redrawn[i].geotiff_path) for i in first]
            if all(n in text for n in names):
                break
            time.sleep(0.2)
        text = open(vrt).read() if os.path.exists(vrt) else ''
        for index, name in zip(first, names):
            self.assertIn(name, text, 'tile_mosaic.vrt names version 2 of tile %d' % index)
            self.assertNotIn(os.path.basename(first[index].geotiff_path) + '<', text)
        deadline = time.time() + 10.0
        counted = 0
        while time.time() < deadline and counted < len(first):
            for s in list(statuses):
                values = {kv.key: kv.value for kv in s.values}
                counted = max(counted, int(values.get('tiles drawn again', 0)))
            time.sleep(0.2)
        self.assertGreaterEqual(counted, len(first), '/diagnostics counts the tiles drawn again')

        # The corrections are saved beside the kept images (at most every 10 s) with the graph's 1-sigma, for the
        # checks made after the dive; a key frame without one has empty sigma columns.
        saved = os.path.join(os.path.dirname(redrawn[min(redrawn)].geotiff_path), '.exocet_images',
                             'graph_corrections.csv')
        deadline = time.time() + 15.0
        rows = []
        while time.time() < deadline:
            if os.path.exists(saved):
                with open(saved) as f:
                    rows = [line.strip().split(',') for line in f]
                if len(rows) == 3 and len(rows[0]) == 6:  # not an earlier run's file
                    break
            time.sleep(0.5)
        self.assertEqual(len(rows), 3, 'graph_corrections.csv: a header and two key frames (%s)' % rows)
        self.assertEqual(rows[0], ['stamp_s', 'east_m', 'north_m', 'east_sigma_m', 'north_sigma_m',
                                   'east_north_correlation'])
        self.assertAlmostEqual(float(rows[1][1]), MOVE_EAST_M, places=6)
        self.assertEqual([float(v) for v in rows[1][3:]], [0.02, 0.03, -0.25])
        self.assertEqual(rows[2][3:], ['', '', ''])


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_graph', TileWriterGraphTest)
