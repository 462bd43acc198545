#!/usr/bin/env python3
"""Checks the tiles of a replayed dive against ground truth (run by tiles_replay.test).

The sample out-and-back dive is replayed through the whole chain (registration, fusion, tile writer). At the end the
checker asks the tile writer to flush its open mosaic, then reads every tile it announced on /mosaic/tile (and by
UDP) back with GDAL: EPSG of the dive's UTM zone, geotransform equal to the announced bounds, world file consistent
with it, metadata; the ground-truth camera track covered; the surveyed checker landmarks found where the tiles say
they are, within a few sigmas of the fused navigation; no partial file left.
"""
import atexit
import csv
import glob
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import time
import unittest

import numpy as np
import rospy
import tf2_ros
import yaml
import rostest
from exocet_msgs.msg import GeoDatum, Tile as TileMsg
from nav_msgs.msg import Odometry, Path
from std_srvs.srv import Trigger

from exocet_mosaic.tile_analysis import Tile, find_checker_saddle, read_world_file


class TilesReplayTest(unittest.TestCase):

    def test_tiles_against_ground_truth(self):
        rospy.init_node('check_tiles_replay')
        bag = rospy.get_param('~bag')
        output_dir = rospy.get_param('~output_dir')
        stem = bag[:-len('.bag')]
        truth = list(csv.DictReader(open(stem + '.ground_truth.csv')))
        landmarks = list(csv.DictReader(open(stem + '.landmarks.csv')))
        tiles_msgs, motions, sigmas, datums = [], [], [], []
        rospy.Subscriber('/mosaic/tile', TileMsg, tiles_msgs.append, queue_size=100)
        rospy.Subscriber('/mosaic/datum', GeoDatum, datums.append, queue_size=2)

        def on_odometry(msg):
            c = msg.pose.covariance
            sigmas.append(math.sqrt(max(np.linalg.eigvalsh(np.array([[c[0], c[1]], [c[6], c[7]]])))))
        rospy.Subscriber('/mosaic/odometry', Odometry, on_odometry, queue_size=1000)
        truth_paths = []
        rospy.Subscriber('/mosaic/ground_truth_path', Path, truth_paths.append, queue_size=10)
        self.tf_buffer = tf2_ros.Buffer()
        self.tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        udp.bind(('127.0.0.1', rospy.get_param('~udp_port')))
        udp.settimeout(0.05)
        datagrams = []
        time.sleep(1.0)
        topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
                  '/nav/altitude', '/nav/datum', '/tf_static', '/ground_truth/odometry']
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics'] + topics,
                                  start_new_session=True)
        # Never leave a player behind: it would reconnect to the next test's master (same port) and replay there.
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        last_count, last_change = -1, time.time()
        published_mid_dive = None
        while time.time() - last_change < 30.0:
            if published_mid_dive is None and len(sigmas) > 50:  # the bag plays: its topics are advertised
                published_mid_dive = {name for name, _ in rospy.get_published_topics()}
            try:
                datagrams.append(json.loads(udp.recv(65536).decode('utf-8')))
            except socket.timeout:
                pass
            if len(sigmas) != last_count:
                last_count, last_change = len(sigmas), time.time()
            if player.poll() is not None and time.time() - last_change > 4.0:
                break
        self.check_rviz_view(truth, truth_paths, published_mid_dive)
        rospy.wait_for_service('/tile_writer/flush', timeout=10.0)
        reply = rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        self.assertTrue(reply.success, reply.message)
        # Settled: the tiles drawn again with their images' gains (the last ones after the flush) announced too; no
        # tile message for 5 s, at most 90 s.
        last_count, last_change, start = len(tiles_msgs), time.time(), time.time()
        while time.time() - last_change < 5.0 and time.time() - start < 90.0:
            try:
                datagrams.append(json.loads(udp.recv(65536).decode('utf-8')))
            except socket.timeout:
                pass
            if len(tiles_msgs) != last_count:
                last_count, last_change = len(tiles_msgs), time.time()
        every_version = list(tiles_msgs)
        newest = {}
        for m in every_version:
            if m.index not in newest or m.version > newest[m.index].version:
                newest[m.index] = m
        tiles_msgs = [newest[i] for i in sorted(newest)]

        self.assertGreaterEqual(len(tiles_msgs), 3, 'a 435-image dive at 120 images per mosaic gives several tiles')
        self.assertTrue(datums, 'the fusion publishes its UTM datum')
        epsg = datums[-1].epsg
        self.assertEqual(epsg, 32631, 'the sample dive lies in UTM zone 31 north')
        self.assertEqual(len(datagrams), len(every_version), 'one UDP datagram per tile and version')
        self.assertEqual(sorted(d['geotiff_path'] for d in datagrams), sorted(m.geotiff_path for m in every_version))
        self.assertFalse(glob.glob(os.path.join(output_dir, '.*partial*')), 'no temporary file is left')

        tiles = []
        for msg in tiles_msgs:
            tile = Tile(msg.geotiff_path)
            tiles.append((msg, tile))
            self.assertEqual(tile.epsg, epsg)
            self.assertEqual(msg.epsg, epsg)
            self.assertEqual((tile.width, tile.height), (msg.width_px, msg.height_px))
            e0, gsd, rot1, n0, rot2, neg_gsd = tile.geotransform
            self.assertEqual((rot1, rot2), (0.0, 0.0), 'north-up')
            self.assertAlmostEqual(gsd, -neg_gsd)
            self.assertAlmostEqual(gsd, msg.gsd_m)
            self.assertAlmostEqual(e0, msg.min_easting_m, places=6)
            self.assertAlmostEqual(n0, msg.max_northing_m, places=6)
            self.assertAlmostEqual(e0 + gsd * tile.width, msg.max_easting_m, places=6)
            world = read_world_file(msg.world_file_path)
            self.assertAlmostEqual(world[0], gsd)
            self.assertAlmostEqual(world[3], -gsd)
            self.assertAlmostEqual(world[4], e0 + gsd / 2, places=6, msg='the world file names the centre of the '
                                   'top-left pixel')
            self.assertAlmostEqual(world[5], n0 - gsd / 2, places=6)
            self.assertEqual(int(tile.metadata['EXOCET_FIRST_FRAME']), msg.first_frame)
            self.assertEqual(int(tile.metadata['EXOCET_LAST_FRAME']), msg.last_frame)
            self.assertGreater(tile.mask.mean(), 0.2, 'the tile holds imagery')
            # Native GSD: camera height ~2.5 m over a 60-degree PAL camera (~3.6 mm) rounded down to 3.2 mm.
            self.assertTrue(0.001 <= gsd <= 0.005, gsd)
        frames = sorted((m.first_frame, m.last_frame) for m, _ in tiles)
        for (_, last), (first, _) in zip(frames, frames[1:]):
            self.assertLessEqual(first, last, 'consecutive tiles share an image (no gap in the mosaic)')

        # The ground-truth camera track: the image centres lie on some tile's data.
        covered = 0
        for row in truth[5:]:
            e, n = float(row['cam_easting_m']), float(row['cam_northing_m'])
            covered += any(t.has_data_at(e, n) for _, t in tiles)
        coverage = covered / float(len(truth) - 5)

        # Landmarks: where the tiles put them vs where they were surveyed.
        sigma_m = float(np.median(sigmas)) if sigmas else float('nan')
        errors = []
        for mark in landmarks:
            e, n, size = float(mark['easting_m']), float(mark['northing_m']), float(mark['size_m'])
            for _, t in tiles:
                if not t.has_data_at(e, n):
                    continue
                found = find_checker_saddle(t, e, n, size, search_m=0.5)
                self.assertIsNotNone(found, 'landmark %s is seen in %s near its surveyed place' % (mark['id'], t.path))
                errors.append(math.hypot(found[0] - e, found[1] - n))
        print('tiles replay: %d tiles, EPSG %d, track coverage %.1f%%, %d landmark sightings, error median %.3f m, '
              'max %.3f m; fused 1-sigma %.3f m' % (len(tiles), epsg, 100 * coverage, len(errors),
                                                   float(np.median(errors)) if errors else -1,
                                                   max(errors) if errors else -1, sigma_m))
        self.assertGreater(coverage, 0.95)
        self.assertGreaterEqual(len(errors), 2)
        # Global placement comes from the fused navigation: a few of its sigmas.
        self.assertLess(max(errors), max(3.0 * sigma_m, 0.05))

        # After the dive: adjust_tiles moves the overlapping tiles into agreement; the adjusted set covers the same
        # track and keeps the landmarks within the same bound.
        adjusted_dir = os.path.join(output_dir, 'adjusted')
        os.makedirs(adjusted_dir)
        done = subprocess.run(['rosrun', 'exocet_mosaic', 'adjust_tiles', '--tiles', output_dir, '--output',
                               adjusted_dir], capture_output=True, text=True, timeout=300)
        self.assertEqual(done.returncode, 0, done.stderr + done.stdout)
        adjusted = [Tile(p) for p in sorted(glob.glob(os.path.join(adjusted_dir, '*_[0-9][0-9][0-9][0-9].tif')))]
        self.assertEqual(len(adjusted), len(tiles))
        for t in adjusted:
            self.assertEqual(t.epsg, epsg)
            self.assertEqual((t.geotransform[2], t.geotransform[4]), (0.0, 0.0), 'north-up')
            self.assertIn('EXOCET_ADJUSTMENT_E_M', t.metadata)
        covered = sum(any(t.has_data_at(float(r['cam_easting_m']), float(r['cam_northing_m'])) for t in adjusted)
                      for r in truth[5:])
        self.assertGreater(covered / float(len(truth) - 5), 0.95)
        adjusted_errors = []
        for mark in landmarks:
            e, n, size = float(mark['easting_m']), float(mark['northing_m']), float(mark['size_m'])
            for t in adjusted:
                if t.has_data_at(e, n):
                    found = find_checker_saddle(t, e, n, size, search_m=0.5)
                    self.assertIsNotNone(found, 'landmark %s is seen in the adjusted %s' % (mark['id'], t.path))
                    adjusted_errors.append(math.hypot(found[0] - e, found[1] - n))
        print('tiles replay, adjusted: %s; landmark error median %.3f m, max %.3f m' % (
            done.stdout.splitlines()[0] if done.stdout else '', float(np.median(adjusted_errors)),
            max(adjusted_errors)))
        self.assertGreaterEqual(len(adjusted_errors), 2)
        self.assertLess(max(adjusted_errors), max(3.0 * sigma_m, 0.05))
        shutil.rmtree(output_dir, ignore_errors=True)  # passed: the tiles (tens of MB) are not kept

    def check_rviz_view(self, truth, truth_paths, published):
        """Every display of launch/exocet.rviz has its topic published by the chain; the ground-truth path follows
        the ground truth."""
        here = os.path.dirname(os.path.abspath(__file__))
        view = yaml.safe_load(open(os.path.join(here, '..', 'src', 'exocet_mosaic', 'launch', 'exocet.rviz')))
        self.assertIsNotNone(published, 'the chain published fused poses while the bag played')
        wanted = []
        for display in view['Visualization Manager']['Displays']:
            topic = display.get('Topic') or display.get('Marker Topic') or display.get('Image Topic')
            if not topic:
                continue
            if display.get('Transport Hint', 'raw') != 'raw':
                topic += '/' + display['Transport Hint']
            wanted.append(topic)
        self.assertGreaterEqual(len(wanted), 8)
        missing = [t for t in wanted if t not in published]
        self.assertEqual(missing, [], 'rviz displays with no publisher')
        self.assertTrue(truth_paths, 'the ground-truth path is published')
        poses = truth_paths[-1].poses
        self.assertGreater(len(poses), 100)
        # In map, the fusion's local frame (rviz draws in single precision): utm -> map is its fixed offset.
        self.assertEqual(truth_paths[-1].header.frame_id, 'map')
        origin = self.tf_buffer.lookup_transform('utm', 'map', rospy.Time(0), rospy.Duration(5.0)).transform.translation
        # The base_link track of the ground truth stays within a metre of the camera track (lever arm).
        cams = np.array([[float(r['cam_easting_m']), float(r['cam_northing_m'])] for r in truth])
        for pose in poses[::10]:
            p = np.array([pose.pose.position.x + origin.x, pose.pose.position.y + origin.y])
            self.assertLess(np.min(np.linalg.norm(cams - p, axis=1)), 1.0)


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'tiles_replay', TilesReplayTest)
