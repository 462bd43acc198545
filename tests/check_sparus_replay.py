#!/usr/bin/env python3
"""The real Sparus II dive (../shared/data/sparus_auv) through the README's commands (run by sparus_replay.test).

The dive's navigation CSV is in a local frame and has depth but no altitude. Imported with `dive_import` and replayed
with `replay_dive`, exactly as a user would:
- in its local frame without a camera height: exit status 1 and one line that says what to give;
- in its local frame with camera_height_m: tiles in the local frame (an engineering CRS named after it, metres), over
  the fused track, with that height in their metadata;
- with a start point (--origin-lat/--origin-lon) and the seabed's depth: tiles in the UTM zone of the start point,
  around it, with the camera height taken from the depth sensor;
- without its navigation (no --nav; --altitude 3): with a start point and heading, replayed with the command
  dive_import prints, tiles in the start point's UTM zone around it; without a start point, replayed with
  `replay_dive BAG OUTDIR` alone (the arguments beside the bag), tiles in the local frame 'map'.
Each replay runs its own roslaunch on its own master port, as on a user's machine.
"""
import csv
import glob
import json
import os
import shlex
import shutil
import socket
import subprocess
import tempfile
import unittest

import rostest
from osgeo import gdal, osr

gdal.UseExceptions()

ORIGIN_LAT, ORIGIN_LON = 39.55, 2.62  # any point: the test checks the tiles land where the start point says
SEABED_DEPTH_M = 16.8                 # the CSV's depth is about 13.8 m: a camera about 3 m above the seabed


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def run(command, timeout_s=300):
    env = dict(os.environ)
    env['ROS_MASTER_URI'] = 'http://127.0.0.1:%d' % free_port()  # a master of its own
    result = subprocess.run(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout_s,
                            universal_newlines=True, start_new_session=True)
    return result.returncode, result.stdout


class SparusReplayTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        cls.data = os.path.join(os.environ.get('EXOCET_SHARED_DATA_DIR', ''), 'sparus_auv')
        if not os.path.isdir(cls.data):
            raise RuntimeError('no Sparus data at %s (EXOCET_SHARED_DATA_DIR)' % cls.data)
        cls.work = tempfile.mkdtemp(prefix='sparus_replay_')

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def import_dive(self, name, extra, nav=True):
        bag, out = self.import_dive_output(name, extra, nav)
        return bag

    def import_dive_output(self, name, extra, nav=True):
        bag = os.path.join(self.work, name + '.bag')
        d = self.data
        status, out = run(['rosrun', 'exocet_mosaic', 'dive_import', '--images', d + '/frames',
                           '--image-times', d + '/frames_index.csv'] +
                          (['--nav', d + '/sparus_snippet.csv'] if nav else []) +
                          ['--camera', d + '/camera_intrinsics.yaml', '--camera-pose', '0,0,0,180,0,-90',
                           '--output', bag] + extra)
        self.assertEqual(status, 0, out)
        return bag, out

    def replay(self, bag, output, extra):
        return self.run_replay(['rosrun', 'exocet_mosaic', 'replay_dive', bag, output, 'ground_truth:=false'] + extra)

    def run_replay(self, command):
        status, out = run(command)
        last = [line for line in out.splitlines() if line.startswith('replay_dive:')]
        return status, (last[-1] if last else ''), out

    def check_near_start_point(self, ds, srs):
        """The tile lies within a few metres of the start point (the dive covers about 2 m)."""
        wgs84 = osr.SpatialReference()
        wgs84.ImportFromEPSG(4326)
        wgs84.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
        srs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
        e, n, _ = osr.CoordinateTransformation(wgs84, srs).TransformPoint(ORIGIN_LON, ORIGIN_LAT)
        e0, gsd, _, n0, _, _ = ds.GetGeoTransform()
        centre_e, centre_n = e0 + gsd * ds.RasterXSize / 2, n0 - gsd * ds.RasterYSize / 2
        self.assertLess(abs(centre_e - e) + abs(centre_n - n), 10.0, (centre_e, centre_n, e, n))

    def tiles_in(self, folder):
        paths = sorted(glob.glob(os.path.join(folder, 'tile_*.tif')))
        self.assertTrue(paths, 'no tile in %s' % folder)
        self.assertFalse(glob.glob(os.path.join(folder, '.*partial*')), 'a temporary file is left')
        return paths

    def check_track_covered(self, path, folder):
        ds = gdal.Open(path)
        e0, gsd, _, n0, _, _ = ds.GetGeoTransform()
        alpha = ds.GetRasterBand(ds.RasterCount).ReadAsArray()
        track = list(csv.DictReader(open(os.path.join(folder, 'fused_track.csv'))))
        self.assertGreater(len(track), 10)
        inside = 0
        for row in track:
            col = int((float(row['easting_m']) - e0) / gsd)
            line = int((n0 - float(row['northing_m'])) / gsd)
            if 0 <= line < ds.RasterYSize and 0 <= col < ds.RasterXSize and alpha[line, col] > 0:
                inside += 1
        self.assertGreaterEqual(inside, 0.9 * len(track), 'the fused track lies on the mosaic')

    def test_local_frame_without_then_with_a_camera_height(self):
        bag = self.import_dive('sparus_local', [])
        output = os.path.join(self.work, 'local_no_height')
        status, line, out = self.replay(bag, output, [])
        self.assertEqual(status, 1, out[-3000:])
        self.assertIn('no tile written', line)
        self.assertIn('camera_height_m:=', line, 'the reason says what to give')
        self.assertFalse(glob.glob(os.path.join(output, 'tile_*')))
        self.assertIn('fusion: no camera height at the image stamps', out, 'the fusion says it as an error')

        output = os.path.join(self.work, 'local')
        status, line, out = self.replay(bag, output, ['camera_height_m:=3.0'])
        self.assertEqual(status, 0, out[-3000:])
        self.assertIn("local frame 'map'", line)
        paths = self.tiles_in(output)
        for path in paths:
            ds = gdal.Open(path)
            srs = osr.SpatialReference(wkt=ds.GetProjection())
            self.assertTrue(srs.IsLocal(), ds.GetProjection())
            self.assertIn("'map'", srs.GetName())
            self.assertEqual(srs.GetLinearUnits(), 1.0)
            self.assertAlmostEqual(float(ds.GetMetadataItem('EXOCET_MEAN_ALTITUDE_M')), 3.0, places=6)
            self.assertTrue(os.path.exists(path[:-4] + '.tfw'))
        self.check_track_covered(paths[0], output)
        summary = json.load(open(os.path.join(output, 'run_summary.json')))
        self.assertEqual(summary['frame'], 'map')
        self.assertEqual(summary['images_received'], 22)

    def test_start_point_and_seabed_depth_give_utm_tiles(self):
        bag = self.import_dive('sparus_geo', ['--origin-lat', str(ORIGIN_LAT), '--origin-lon', str(ORIGIN_LON)])
        output = os.path.join(self.work, 'geo')
        status, line, out = self.replay(bag, output, ['seabed_depth_m:=%g' % SEABED_DEPTH_M])
        self.assertEqual(status, 0, out[-3000:])
        self.assertIn('EPSG:32631', line)
        paths = self.tiles_in(output)
        ds = gdal.Open(paths[0])
        srs = osr.SpatialReference(wkt=ds.GetProjection())
        self.assertEqual(srs.GetAuthorityCode(None), '32631')
        self.check_near_start_point(ds, srs)
        # Height from the depth sensor: the seabed's depth minus the camera's (13.6-14.0 m in the CSV).
        altitude = float(ds.GetMetadataItem('EXOCET_MEAN_ALTITUDE_M'))
        self.assertGreater(altitude, 2.5)
        self.assertLess(altitude, 3.5)
        self.check_track_covered(paths[0], output)

    def test_without_navigation_start_point_gives_utm_tiles(self):
        bag, out = self.import_dive_output('sparus_nonav_geo', [
            '--altitude', '3', '--origin-lat', str(ORIGIN_LAT), '--origin-lon', str(ORIGIN_LON), '--heading', '0'],
            nav=False)
        self.assertIn('no navigation (22 altitude)', out)
        # The command the importer prints, run as printed.
        commands = [line.strip() for line in out.splitlines()
                    if line.strip().startswith('rosrun exocet_mosaic replay_dive ')]
        self.assertEqual(len(commands), 1, out)
        command = shlex.split(commands[0])
        self.assertIn('fusion_preset:=images_only', command)
        self.assertIn('origin_lat:=39.55000000', command)
        output = command[4]
        status, line, log = self.run_replay(command)
        self.assertEqual(status, 0, log[-3000:])
        self.assertIn('EPSG:32631', line)
        paths = self.tiles_in(output)
        ds = gdal.Open(paths[0])
        srs = osr.SpatialReference(wkt=ds.GetProjection())
        self.assertEqual(srs.GetAuthorityCode(None), '32631')
        self.check_near_start_point(ds, srs)
        # The camera height is the constant altitude (the camera at base_link's origin).
        self.assertAlmostEqual(float(ds.GetMetadataItem('EXOCET_MEAN_ALTITUDE_M')), 3.0, places=3)
        self.check_track_covered(paths[0], output)
        self.assertEqual(json.load(open(os.path.join(output, 'run_summary.json')))['frame'], 'utm')

    def test_without_navigation_or_start_point_gives_local_tiles(self):
        bag = self.import_dive('sparus_nonav_local', ['--altitude', '3'], nav=False)
        self.assertTrue(os.path.exists(bag + '.replay.json'))
        output = os.path.join(self.work, 'nonav_local')
        status, line, out = self.run_replay(['rosrun', 'exocet_mosaic', 'replay_dive', bag, output])
        self.assertEqual(status, 0, out[-3000:])
        self.assertIn("local frame 'map'", line)
        self.assertIn("the tiles are in that local frame", out, 'the fusion says the tiles are not geo-referenced')
        paths = self.tiles_in(output)
        for path in paths:
            ds = gdal.Open(path)
            srs = osr.SpatialReference(wkt=ds.GetProjection())
            self.assertTrue(srs.IsLocal(), ds.GetProjection())
            self.assertIn("'map'", srs.GetName())
            self.assertEqual(srs.GetLinearUnits(), 1.0)
            self.assertAlmostEqual(float(ds.GetMetadataItem('EXOCET_MEAN_ALTITUDE_M')), 3.0, places=3)
        self.check_track_covered(paths[0], output)
        # The track starts at the local frame's origin.
        first = next(csv.DictReader(open(os.path.join(output, 'fused_track.csv'))))
        self.assertLess(abs(float(first['easting_m'])) + abs(float(first['northing_m'])), 0.5, first)


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'sparus_replay', SparusReplayTest)
