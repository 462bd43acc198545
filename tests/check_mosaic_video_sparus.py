#!/usr/bin/env python3
"""mosaic_video on the real Sparus II video (../shared/data/sparus_auv), run by mosaic_video_sparus.test.

`rosrun exocet_mosaic mosaic_video sparus_snippet.mp4 --origin-lat 39.55 --origin-lon 2.62 --altitude 3` with the
dive's intrinsics, then once more with its navigation CSV (--nav, x and y offsets from the start point): each run
must place every frame and write GeoTIFF tiles in UTM zone 31 N (EPSG 32631) around the start point, with
track.csv, overview.png and summary.json beside them. Without --camera the clip (22 frames) cannot self-calibrate:
the run says so and marks the scale approximate.
"""
import csv
import glob
import json
import os
import shutil
import subprocess
import tempfile
import unittest

import rostest
from osgeo import gdal, osr

gdal.UseExceptions()

ORIGIN_LAT, ORIGIN_LON = 39.55, 2.62
ALTITUDE_M = 3.0


class MosaicVideoSparusTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        cls.data = os.path.join(os.environ.get('EXOCET_SHARED_DATA_DIR', ''), 'sparus_auv')
        if not os.path.isdir(cls.data):
            raise RuntimeError('no Sparus data at %s (EXOCET_SHARED_DATA_DIR)' % cls.data)
        cls.work = tempfile.mkdtemp(prefix='mosaic_video_sparus_')

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.work, ignore_errors=True)

    def mosaic(self, name, extra):
        output = os.path.join(self.work, name)
        command = ['rosrun', 'exocet_mosaic', 'mosaic_video', os.path.join(self.data, 'sparus_snippet.mp4'),
                   '--origin-lat', str(ORIGIN_LAT), '--origin-lon', str(ORIGIN_LON), '--altitude', str(ALTITUDE_M),
                   '--output', output] + extra
        result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=240,
                                universal_newlines=True)
        self.assertEqual(result.returncode, 0, result.stdout + result.stderr)
        with open(os.path.join(output, 'summary.json')) as f:
            summary = json.load(f)
        return output, summary, result

    def check_geo_tiles(self, output, summary):
        self.assertEqual(summary['frames_read'], 22)
        self.assertEqual(summary['frames_placed'], 22, summary)
        self.assertEqual(summary['frame'], 'utm')
        self.assertEqual(summary['epsg'], 32631)
        self.assertIsNone(summary['reason'])
        paths = sorted(glob.glob(os.path.join(output, 'tile_[0-9][0-9][0-9][0-9].tif')))
        self.assertGreaterEqual(len(paths), 1)
        self.assertEqual(len(paths), summary['tiles_written'])
        wgs84 = osr.SpatialReference()
        wgs84.ImportFromEPSG(4326)
        wgs84.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
        for path in paths:
            ds = gdal.Open(path)
            srs = osr.SpatialReference(wkt=ds.GetProjection())
            self.assertEqual(srs.GetAuthorityCode(None), '32631', path)
            srs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
            e, n, _ = osr.CoordinateTransformation(wgs84, srs).TransformPoint(ORIGIN_LON, ORIGIN_LAT)
            e0, gsd, _, n0, _, _ = ds.GetGeoTransform()
            centre_e, centre_n = e0 + gsd * ds.RasterXSize / 2, n0 - gsd * ds.RasterYSize / 2
            # The clip covers about 2 m: its tile lies within a few metres of the start point.
            self.assertLess(abs(centre_e - e) + abs(centre_n - n), 10.0, (path, centre_e, centre_n, e, n))
            self.assertGreater(gsd, 0.001)
            self.assertLess(gsd, 0.05)
            self.assertAlmostEqual(float(ds.GetMetadataItem('EXOCET_MEAN_ALTITUDE_M')), ALTITUDE_M, delta=0.3)
            ds.GetRasterBand(1).ReadAsArray()  # complete
        with open(os.path.join(output, 'track.csv')) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual(len(rows), 22)
        self.assertTrue(all(r['placed'] == '1' for r in rows))
        self.assertTrue(os.path.isfile(os.path.join(output, 'overview.png')))

    def test_images_only_from_a_start_point(self):
        output, summary, _ = self.mosaic('images_only', ['--camera', os.path.join(self.data, 'camera_intrinsics.yaml')])
        self.check_geo_tiles(output, summary)
        self.assertEqual(summary['camera'], 'file')
        self.assertFalse(summary['scale_approximate'])
        self.assertIsNone(summary['navigation'])

    def test_with_the_navigation(self):
        output, summary, _ = self.mosaic('nav', ['--camera', os.path.join(self.data, 'camera_intrinsics.yaml'),
                                                 '--nav', os.path.join(self.data, 'sparus_snippet.csv')])
        self.check_geo_tiles(output, summary)
        self.assertTrue(summary['navigation'].endswith('sparus_snippet.csv'))

    def test_without_intrinsics_the_scale_is_approximate(self):
        output, summary, result = self.mosaic('no_camera', [])
        self.check_geo_tiles(output, summary)
        self.assertIn(summary['camera'], ('selfcal', 'hfov'))
        if summary['camera'] == 'hfov':
            self.assertTrue(summary['scale_approximate'])
            self.assertIn('self-calibration refused', result.stderr)
            self.assertTrue(os.path.isfile(os.path.join(output, 'SCALE_APPROXIMATE.txt')))
            ds = gdal.Open(os.path.join(output, 'tile_0000.tif'))
            self.assertEqual(ds.GetMetadataItem('EXOCET_SCALE_APPROXIMATE'), 'true')


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'mosaic_video_sparus', MosaicVideoSparusTest)
