#!/usr/bin/env python3
"""Feeds tile_writer_node frames faster than it writes their tiles and checks that the closed mosaics waiting for the
writer stay within ~max_queued_tiles, that the composition's waits are reported, and that nothing is lost."""
import glob
import os
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from osgeo import gdal

from tile_writer_node_check import chain_publishers, flush_tile_writer, publish_frames, wait_for_subscribers

FRAMES = 40
OUTPUT_DIR = os.path.join(os.environ.get('ROS_HOME', '/tmp'), 'test_tile_writer_backlog')


class TileWriterBacklogTest(unittest.TestCase):

    def test_queued_tiles_stay_bounded(self):
        for old in glob.glob(os.path.join(OUTPUT_DIR, 'tile_*')):
            os.remove(old)
        rospy.init_node('tile_writer_backlog_check')
        latest = {}

        def on_diagnostics(msg):
            for s in msg.status:
                if 'tile' in s.name:
                    latest['status'] = s
                    latest['values'] = {kv.key: kv.value for kv in s.values}
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        publishers = chain_publishers()
        self.assertTrue(wait_for_subscribers([publishers[k] for k in ('images', 'motions', 'odometry', 'heights')]))
        publish_frames(publishers, FRAMES, rospy.Time(1000.0))
        # The writer is behind at the end of the input: the flush waits until every closed mosaic is on disk.
        reply = flush_tile_writer(150.0)
        self.assertTrue(reply is not None and reply.success, reply.message if reply else 'no reply')
        time.sleep(2.5)  # one more /diagnostics after the flush
        values = latest.get('values', {})
        self.assertEqual(int(values['images received']), FRAMES, values)
        self.assertEqual(int(values['tiles lost']), 0)
        self.assertEqual(int(values['write failures']), 0)
        # The bound: never more closed mosaics waiting for the writer than ~max_queued_tiles (1 here).
        self.assertLessEqual(int(values['tiles queued (most at once)']), 1, values)
        # And it was reached: the composition waited for the writer, and the time is reported.
        self.assertGreaterEqual(int(values['composition waits for the writer']), 1, values)
        self.assertGreater(float(values['composition wait for the writer (s)']), 0.0, values)
        written = int(values['tiles written'])
        self.assertGreaterEqual(written, 4, 'frames 4 per mosaic, about half of them composed')
        tiles = sorted(glob.glob(os.path.join(OUTPUT_DIR, 'tile_[0-9][0-9][0-9][0-9].tif')))
        self.assertEqual(len(tiles), written, tiles)
        self.assertEqual(len(glob.glob(os.path.join(OUTPUT_DIR, 'tile_[0-9][0-9][0-9][0-9].kmz'))), written,
                         'a KMZ beside each tile (grey images: the KMZ is made RGBA)')
        for path in tiles:
            dataset = gdal.Open(path)
            self.assertIsNotNone(dataset, path)
            self.assertGreater(dataset.RasterXSize, 2000, 'large tiles, slow to write: ' + path)


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_backlog', TileWriterBacklogTest)
