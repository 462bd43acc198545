#!/usr/bin/env python3
"""Unit tests of exocet_mosaic.tile_analysis on synthetic GeoTIFF tiles (no master, no bag): which files of a tile
folder are the tiles (versions), and the brightness agreement of overlapping tiles aligned by their measured shift.

usage: test_tile_analysis.py [--junit FILE.xml]   (catkin: run_tests_exocet_mosaic_python)
"""
import argparse
import math
import os
import shutil
import sys
import tempfile
import time
import unittest
from xml.sax.saxutils import escape, quoteattr

import cv2
import numpy as np
from osgeo import gdal, osr

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'python'))
from exocet_mosaic import tile_analysis  # noqa: E402

GSD_M = 0.004  # 4 mm/px: pair_shift works at that scale without resampling
E0_M, N0_M = 734390.0, 4772750.0


def texture(height, width, seed):
    """A seabed-like grey texture (blurred noise, 8-bit, 40..210)."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.normal(0.0, 1.0, (height, width)).astype(np.float32), (0, 0), 2.0)
    t = (t - t.min()) / (t.max() - t.min())
    return (40 + 170 * t).astype(np.uint8)


def write_tile(path, grey, col0_px, row0_px, gain=1.0, offset_grey=0.0, no_data=None):
    """An RGB + alpha GeoTIFF of grey (R = G = B, times gain plus offset) whose pixel (0, 0) is at (col0, row0) of
    the grid whose pixel (0, 0) is at E0_M, N0_M; no_data: (rows, cols) slices left without data."""
    h, w = grey.shape
    value = np.clip(np.rint(grey.astype(np.float64) * gain + offset_grey), 0, 255).astype(np.uint8)
    alpha = np.full((h, w), 255, np.uint8)
    if no_data is not None:
        alpha[no_data] = 0
        value = value.copy()
        value[no_data] = 0
    ds = gdal.GetDriverByName('GTiff').Create(path, w, h, 4, gdal.GDT_Byte, ['PHOTOMETRIC=RGB', 'ALPHA=YES'])
    ds.SetGeoTransform([E0_M + col0_px * GSD_M, GSD_M, 0.0, N0_M - row0_px * GSD_M, 0.0, -GSD_M])
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32631)
    ds.SetProjection(srs.ExportToWkt())
    for band, data in enumerate((value, value, value, alpha)):
        ds.GetRasterBand(band + 1).WriteArray(data)
    ds.GetRasterBand(4).SetColorInterpretation(gdal.GCI_AlphaBand)
    ds.FlushCache()
    ds = None


class TileNamesTest(unittest.TestCase):

    def setUp(self):
        self.folder = tempfile.mkdtemp(prefix='tile_analysis_test_')

    def tearDown(self):
        shutil.rmtree(self.folder, ignore_errors=True)

    def test_parse_tile_name(self):
        self.assertEqual(tile_analysis.parse_tile_name('dive_0003.tif'), ('dive', 3, 1))
        self.assertEqual(tile_analysis.parse_tile_name('dive_0003_v2.tif'), ('dive', 3, 2))
        self.assertEqual(tile_analysis.parse_tile_name('my_dive_12345_v10.tif'), ('my_dive', 12345, 10))
        for name in ('dive_0003.cog.tif', 'dive_0003.tif.partial', 'dive_0003_v2.tif.partial', '.dive_0003.tif',
                     'dive_0003.tfw', 'dive_003.tif', 'dive_0003_v.tif', 'tiles_manifest.json'):
            self.assertIsNone(tile_analysis.parse_tile_name(name), name)

    def test_highest_version_per_index(self):
        for name in ('dive_0000.tif', 'dive_0001.tif', 'dive_0001_v2.tif', 'dive_0001_v3.tif', 'dive_0002_v2.tif',
                     'dive_0003.cog.tif', 'dive_0004.tif.partial', '.dive_0005.tif', 'dive_0000_v4.tif.partial',
                     'dive_0010.tif', 'dive_0001_v3.cog.tif', 'tiles_manifest.json'):
            open(os.path.join(self.folder, name), 'w').close()
        names = [os.path.basename(p) for p in tile_analysis.tile_paths(self.folder)]
        self.assertEqual(names, ['dive_0000.tif', 'dive_0001_v3.tif', 'dive_0002_v2.tif', 'dive_0010.tif'])

    def test_tile_index_and_version(self):
        write_tile(os.path.join(self.folder, 'dive_0007_v2.tif'), texture(120, 130, 1), 0, 0)
        tile = tile_analysis.read_tiles(self.folder)[0]
        self.assertEqual((tile.index, tile.version), (7, 2))
        self.assertEqual(tile.luma.dtype, np.uint8)


class HistogramMedianTest(unittest.TestCase):

    def test_as_numpy_median(self):
        rng = np.random.default_rng(3)
        for n in (1, 2, 3, 10, 11, 1000, 1001):
            values = rng.integers(0, 256, n)
            hist = np.bincount(values, minlength=256)
            self.assertAlmostEqual(tile_analysis.histogram_median(hist), float(np.median(values)), msg='n=%d' % n)
        self.assertIsNone(tile_analysis.histogram_median(np.zeros(256, np.int64)))


class OverlapColourTest(unittest.TestCase):
    """Tile b shows the seabed 150 px east of tile a, 12 grey levels brighter, and its geotransform is off by
    (+4, -3) px (a navigation error): the shift measured by pair_shift aligns it, and the colour figures then see
    the level step alone."""

    def setUp(self):
        self.folder = tempfile.mkdtemp(prefix='tile_analysis_test_')
        seabed = texture(420, 620, 7)
        write_tile(os.path.join(self.folder, 't_0000.tif'), seabed[10:410, 0:400], 0, 10,
                   no_data=(slice(0, 60), slice(0, 60)))
        # b's pixel (0, 0) shows seabed (row 10, col 150), but its geotransform says (row 10 - 3, col 150 + 4).
        write_tile(os.path.join(self.folder, 't_0002.tif'), seabed[10:410, 150:550], 154, 7, offset_grey=12)
        self.a, self.b = tile_analysis.read_tiles(self.folder)

    def tearDown(self):
        shutil.rmtree(self.folder, ignore_errors=True)

    def test_aligned_by_the_measured_shift(self):
        shift = tile_analysis.pair_shift(self.a, self.b, patch_px=192)
        self.assertIsNotNone(shift)
        self.assertLess(math.hypot(abs(shift['dx_px']) - 4, abs(shift['dy_px']) - 3), 0.5, shift)
        aligned = tile_analysis.pair_colour_difference(self.a, self.b, shift['dx_px'], shift['dy_px'])
        self.assertIsNotNone(aligned)
        self.assertAlmostEqual(aligned['level_step_grey'], -12.0, delta=0.6)
        self.assertEqual(aligned['abs_diff_median_grey'], 12.0)
        # Overlap 250 x 400 px less the eroded edges (3 px each side where a tile ends).
        self.assertGreater(aligned['pixels'], 0.9 * 244 * 394)
        misaligned = tile_analysis.pair_colour_difference(self.a, self.b, 0.0, 0.0)
        self.assertGreater(misaligned['abs_diff_median_grey'], 14.0)  # the texture no longer cancels

    def test_figures_over_pairs(self):
        pairs = tile_analysis.overlapping_pair_shifts([self.a, self.b])
        self.assertEqual(len(pairs), 1)
        self.assertFalse(pairs[0]['consecutive'])  # indices 0 and 2
        fig = tile_analysis.overlap_colour_figures([self.a, self.b], pairs)
        self.assertEqual(fig['overlap_colour_pairs'], 1)
        self.assertAlmostEqual(fig['overlap_level_step_max_grey'], 12.0, delta=0.6)
        self.assertEqual(fig['overlap_abs_diff_median_grey'], 12.0)
        # A pair without a shift is not measured.
        fig = tile_analysis.overlap_colour_figures([self.a, self.b], [dict(pairs[0], dx_px=None, dy_px=None)])
        self.assertEqual(fig['overlap_colour_pairs'], 0)
        self.assertIsNone(fig['overlap_level_step_max_grey'])
        self.assertIsNone(fig['overlap_abs_diff_median_grey'])

    def test_edges_eroded(self):
        # Without erosion the no-data corner's neighbours count; with it, 3 px less on each data edge.
        full = tile_analysis.pair_colour_difference(self.a, self.b, 4.0, 3.0, erode_px=0)
        eroded = tile_analysis.pair_colour_difference(self.a, self.b, 4.0, 3.0, erode_px=3)
        self.assertLess(eroded['pixels'], full['pixels'])


def write_junit(path, suite_name, result, tests, seconds):
    failed = {t.id(): msg for t, msg in result.failures + result.errors}
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, 'w') as f:
        f.write('<?xml version="1.0" encoding="utf-8"?>\n')
        f.write('<testsuite name=%s tests="%d" failures="%d" errors="0" time="%.1f">\n' % (
            quoteattr(suite_name), len(tests), len(failed), seconds))
        for t in tests:
            cls, name = t.id().rsplit('.', 1)
            f.write('  <testcase classname=%s name=%s>' % (quoteattr(cls), quoteattr(name)))
            if t.id() in failed:
                f.write('<failure message="failed">%s</failure>' % escape(failed[t.id()]))
            f.write('</testcase>\n')
        f.write('</testsuite>\n')


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--junit', help='also write the results as JUnit XML (catkin_test_results reads it)')
    args = parser.parse_args()
    gdal.UseExceptions()
    suite = unittest.defaultTestLoader.loadTestsFromModule(sys.modules[__name__])
    tests = []

    def collect(s):
        for t in s:
            if isinstance(t, unittest.TestSuite):
                collect(t)
            else:
                tests.append(t)
    collect(suite)
    start = time.time()
    result = unittest.TextTestRunner(verbosity=2).run(suite)
    if args.junit:
        write_junit(args.junit, 'tile_analysis', result, tests, time.time() - start)
    return 0 if result.wasSuccessful() else 1


if __name__ == '__main__':
    sys.exit(main())
