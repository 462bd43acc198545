#!/usr/bin/env python3
"""The tile writer's output folder fills up (run by tile_writer_disk_full.test; root: it mounts a small tmpfs as the
folder, and says it skipped otherwise).

Synthetic frames (tile_writer_node_check.publish_frames) go straight to a tile writer started here. Two tiles are
written; then the folder is filled to the last byte, twice:
1. while two mosaics close (as many as ~max_failed_tiles_kept keeps for a retry);
2. while four close (more than it keeps: the oldest are dropped and counted as lost).
Each time, while the disk is full: /diagnostics is ERROR with the write error (No space left on device), at most
~max_failed_tiles_kept closed mosaics wait in memory, the open mosaic stays within ~max_memory_mb, and the frames go on
being composed. Then the space is freed: the tiles kept are written (no index skipped), diagnostics say so, and every
tile written before is intact (same bytes). The episodes survived go to out/bench/reliability.json
(disk_full_survived).
"""
import errno
import glob
import hashlib
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from exocet_msgs.msg import ImageMotion, Tile as TileMsg
from nav_msgs.msg import Odometry
from osgeo import gdal
from sensor_msgs.msg import CompressedImage, Image, Range

from exocet_mosaic.reliability import update_reliability, workspace_bench_dir
from tile_writer_node_check import publish_frames

gdal.UseExceptions()

MOUNT_MB = 16
FRAMES_PER_MOSAIC = 20
MAX_FAILED_TILES_KEPT = 2
MAX_MEMORY_MB = 20.0


def fill(folder):
    """Writes folder/filler until the file system refuses a byte more."""
    fd = os.open(os.path.join(folder, 'filler'), os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        for block in (1 << 20, 1 << 12, 1):
            while True:
                try:
                    os.write(fd, b'\0' * block)
                except OSError as e:
                    if e.errno != errno.ENOSPC:
                        raise
                    break
    finally:
        os.close(fd)


def tile_files(folder):
    return {os.path.basename(p): hashlib.sha256(open(p, 'rb').read()).hexdigest()
            for p in glob.glob(os.path.join(folder, 'tile_*.t[if][fw]'))}


class TileWriterDiskFullTest(unittest.TestCase):

    def setUp(self):
        rospy.init_node('tile_writer_disk_full_check', anonymous=True)
        self.root = tempfile.mkdtemp(prefix='tile_writer_disk_full_')
        self.folder = os.path.join(self.root, 'tiles')
        os.makedirs(self.folder)
        self.mounted, self.node = False, None
        if os.geteuid() != 0:
            self.skipTest('mounting a small tmpfs as the full output folder needs root: skipped')
        done = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=%dm' % MOUNT_MB, 'tmpfs', self.folder],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if done.returncode != 0:
            self.skipTest('cannot mount a tmpfs here (%s): skipped' % done.stdout.strip())
        self.mounted = True

    def tearDown(self):
        if self.node is not None and self.node.poll() is None:
            self.node.send_signal(signal.SIGINT)
            try:
                self.node.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.node.pid, signal.SIGKILL)
        if self.mounted:
            if subprocess.run(['umount', self.folder]).returncode != 0:
                subprocess.run(['umount', '-l', self.folder])
        shutil.rmtree(self.root, ignore_errors=True)

    def start_writer(self):
        for name, value in {'output_dir': self.folder, 'utm_zone': 31, 'frames_per_mosaic': FRAMES_PER_MOSAIC,
                            'lighting/enabled': False, 'retry_period_s': 1.0,
                            'max_failed_tiles_kept': MAX_FAILED_TILES_KEPT, 'max_memory_mb': MAX_MEMORY_MB,
                            'image_gain_compensation': False, 'preview_period_s': 0.0}.items():
            rospy.set_param('/tile_writer/' + name, value)
        self.log = open(os.path.join(self.root, 'tile_writer.log'), 'w')
        self.node = subprocess.Popen(['rosrun', 'exocet_mosaic', 'tile_writer_node', '__name:=tile_writer'],
                                     stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)

    def wait_status(self, condition, timeout_s, what):
        """The first tile writer status after now that satisfies condition(level, message, values)."""
        since = time.time()
        deadline = since + timeout_s
        while time.time() < deadline:
            for wall, level, message, values in list(self.statuses):
                if wall >= since and condition(level, message, values):
                    return level, message, values
            time.sleep(0.1)
        self.fail('no /diagnostics of the tile writer %s within %.0f s; last: %s' %
                  (what, timeout_s, self.statuses[-1][1:] if self.statuses else None))

    def test_full_disk_twice(self):
        self.start_writer()
        self.statuses, tiles = [], []

        def on_diagnostics(msg):
            for s in msg.status:
                if s.hardware_id.startswith('tile writer'):
                    self.statuses.append((time.time(), s.level, s.message, {kv.key: kv.value for kv in s.values}))
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        rospy.Subscriber('/mosaic/tile', TileMsg, tiles.append, queue_size=100)
        pubs = {'images': rospy.Publisher('/camera/image_raw', Image, queue_size=200),
                'compressed': rospy.Publisher('/camera/image_raw/compressed', CompressedImage, queue_size=10),
                'motions': rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=200),
                'odometry': rospy.Publisher('/mosaic/odometry', Odometry, queue_size=200),
                'heights': rospy.Publisher('/mosaic/camera_height', Range, queue_size=200)}
        deadline = time.time() + 30.0
        while time.time() < deadline and any(p.get_num_connections() == 0 for k, p in pubs.items()
                                             if k != 'compressed'):
            time.sleep(0.1)
        start = rospy.Time(1000.0)
        sent = [0]

        def publish(count):
            publish_frames(pubs, count, start + rospy.Duration(0.2 * sent[0]), first=sent[0])
            sent[0] += count

        publish(2 * FRAMES_PER_MOSAIC + 2)
        self.wait_status(lambda lv, m, v: int(v.get('tiles written', 0)) >= 2, 30.0, 'with two tiles written')
        survived = 0
        lost_before = 0
        for episode, mosaics in ((1, MAX_FAILED_TILES_KEPT), (2, 2 * MAX_FAILED_TILES_KEPT)):
            before = tile_files(self.folder)
            written = int(self.statuses[-1][3]['tiles written'])
            composed = int(self.statuses[-1][3]['frames composed'])
            fill(self.folder)
            publish(mosaics * FRAMES_PER_MOSAIC)
            lost_expected = max(0, mosaics - MAX_FAILED_TILES_KEPT)
            level, message, values = self.wait_status(
                lambda lv, m, v: lv == DiagnosticStatus.ERROR and
                int(v['write failures']) > 0 and int(v['tiles lost']) >= lost_before + lost_expected and
                int(v['tiles waiting for a retry']) == MAX_FAILED_TILES_KEPT, 30.0,
                'saying ERROR with the write error while the disk is full (episode %d)' % episode)
            print('disk full, episode %d: %s; %s' % (episode, message, {k: values[k] for k in (
                'tiles waiting for a retry', 'tiles lost', 'frames composed', 'frames not on disk yet',
                'open mosaic memory (MB)', 'last write error')}))
            self.assertIn('No space left on device', message + values['last write error'])
            self.assertGreater(int(values['frames composed']), composed, 'the frames go on being composed')
            during = [s for s in self.statuses if s[0] >= self.statuses[-1][0] - 5.0]
            for _, _, _, v in during:
                self.assertLessEqual(int(v['tiles waiting for a retry']), MAX_FAILED_TILES_KEPT)
                self.assertLessEqual(float(v['open mosaic memory (MB)']), MAX_MEMORY_MB)
            waiting = int(values['tiles waiting for a retry'])
            lost_before = int(values['tiles lost'])
            self.assertEqual(tile_files(self.folder), before, 'nothing on disk changes while it is full')

            os.unlink(os.path.join(self.folder, 'filler'))
            _, message, values = self.wait_status(
                lambda lv, m, v: int(v['tiles waiting for a retry']) == 0 and int(v['tiles queued']) == 0 and
                int(v['tiles written']) >= written + waiting, 30.0,
                'writing the kept tiles once space returns (episode %d)' % episode)
            self.assertEqual(int(values['tiles written']), written + waiting)
            after = tile_files(self.folder)
            self.assertEqual({k: after.get(k) for k in before}, before, 'every tile written before is intact')
            indices = sorted(int(n[5:9]) for n in after if n.endswith('.tif'))
            self.assertEqual(indices, list(range(len(indices))), 'no tile index skipped')
            for name in after:
                if name.endswith('.tif'):
                    dataset = gdal.Open(os.path.join(self.folder, name))
                    self.assertGreaterEqual(dataset.RasterCount, 2, name)  # grey (or BGR) and alpha
                    dataset.GetRasterBand(1).Checksum()  # every block readable
            self.assertFalse(glob.glob(os.path.join(self.folder, '.*partial*')), 'no temporary left')
            survived += 1
            print('disk full, episode %d survived: %d tiles kept and written after the space returned, %d lost; %s' %
                  (episode, waiting, lost_expected, message))

        # At the end, the summary counts the tiles the full disk cost.
        self.node.send_signal(signal.SIGINT)
        self.node.wait(timeout=60.0)
        summary = json.load(open(os.path.join(self.folder, 'run_summary.json')))
        self.assertEqual(summary['tiles_not_written'], lost_before)
        update_reliability({'disk_full_survived': survived}, workspace_bench_dir(__file__))


if __name__ == '__main__':
    rostest.rosrun('exocet_mosaic', 'tile_writer_disk_full', TileWriterDiskFullTest)
