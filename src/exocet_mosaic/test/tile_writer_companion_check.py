#!/usr/bin/env python3
"""Puts a directory in the way of tile 1's KMZ and checks that tile_writer_node still writes that tile's GeoTIFF,
reports the missing KMZ on /diagnostics, loses no tile, and writes the KMZ of the others."""
import glob
import os
import shutil
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import Tile
from osgeo import gdal

from tile_writer_node_check import chain_publishers, flush_tile_writer, publish_frames, wait_for_subscribers

FRAMES = 24
OUTPUT_DIR = os.path.join(os.environ.get('ROS_HOME', '/tmp'), 'test_tile_writer_companion')
BLOCKER = os.path.join(OUTPUT_DIR, '.tile_0001.partial.kmz')


class TileWriterCompanionTest(unittest.TestCase):

    def test_a_tile_without_its_kmz_is_written_and_reported(self):
        os.makedirs(OUTPUT_DIR, exist_ok=True)
        for old in glob.glob(os.path.join(OUTPUT_DIR, 'tile_*')):
            os.remove(old)
        if os.path.isdir(BLOCKER):
            shutil.rmtree(BLOCKER)
        os.mkdir(BLOCKER)  # GDAL's KMZ driver cannot create a file where a directory is
        rospy.init_node('tile_writer_companion_check')
        latest = {}
        announced = {}

        def on_diagnostics(msg):
            for s in msg.status:
                if 'tile' in s.name:
                    latest['values'] = {kv.key: kv.value for kv in s.values}

        def on_tile(msg):
            announced[msg.index] = msg
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        rospy.Subscriber('/mosaic/tile', Tile, on_tile, queue_size=100)
        publishers = chain_publishers()
        self.assertTrue(wait_for_subscribers([publishers[k] for k in ('images', 'motions', 'odometry', 'heights')]))
        publish_frames(publishers, FRAMES, rospy.Time(1000.0))
        reply = flush_tile_writer(60.0)
        self.assertTrue(reply is not None and reply.success, reply.message if reply else 'no reply')
        time.sleep(2.5)  # one more /diagnostics after the flush
        try:
            values = latest.get('values', {})
            written = int(values['tiles written'])
            self.assertGreaterEqual(written, 3, values)
            self.assertEqual(int(values['write failures']), 0, values)
            self.assertEqual(int(values['tiles lost']), 0, values)
            self.assertEqual(int(values['companion files not written (COG, KMZ)']), 1, values)
            self.assertIn('tile 1 KMZ', values['last companion file not written'])
            tiles = sorted(glob.glob(os.path.join(OUTPUT_DIR, 'tile_[0-9][0-9][0-9][0-9].tif')))
            self.assertEqual(len(tiles), written, tiles)
            for path in tiles:
                self.assertIsNotNone(gdal.Open(path), path)
            kmz = sorted(os.path.basename(p) for p in glob.glob(os.path.join(OUTPUT_DIR, 'tile_*.kmz')))
            self.assertNotIn('tile_0001.kmz', kmz)
            self.assertEqual(len(kmz), written - 1, kmz)
            # Announced without a KMZ path, the others with theirs.
            deadline = time.time() + 5.0
            while 1 not in announced and time.time() < deadline:
                time.sleep(0.1)
            self.assertIn(1, announced)
            self.assertEqual(announced[1].kmz_path, '')
            self.assertTrue(announced[1].geotiff_path.endswith('tile_0001.tif'))
            self.assertTrue(announced[0].kmz_path.endswith('tile_0000.kmz'))
        finally:
            shutil.rmtree(BLOCKER, ignore_errors=True)


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_companion', TileWriterCompanionTest)
