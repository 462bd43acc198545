"""Reading GeoTIFF tiles back and measuring them against ground truth (shared by the tile tests and bench_tiles).

Needs python3-gdal and python3-opencv. Coordinates: UTM easting/northing (m); a tile's geotransform is
[E0, gsd, 0, N0, 0, -gsd] (north-up), pixel (col, row) -> E0 + (col + 0.5) * gsd, N0 - (row + 0.5) * gsd at its centre.
"""
import math

import cv2
import numpy as np
from osgeo import gdal, osr

gdal.UseExceptions()


class Tile:
    """A GeoTIFF tile read back with GDAL: grey image, data mask, geotransform, EPSG, metadata."""

    def __init__(self, path):
        dataset = gdal.Open(path)
        self.path = path
        self.width, self.height = dataset.RasterXSize, dataset.RasterYSize
        self.geotransform = dataset.GetGeoTransform()
        srs = osr.SpatialReference(wkt=dataset.GetProjection())
        srs.AutoIdentifyEPSG()
        self.epsg = int(srs.GetAuthorityCode(None) or 0)
        self.metadata = dataset.GetMetadata()
        bands = [dataset.GetRasterBand(i + 1) for i in range(dataset.RasterCount)]
        colour = [b for b in bands if b.GetColorInterpretation() != gdal.GCI_AlphaBand]
        alpha = [b for b in bands if b.GetColorInterpretation() == gdal.GCI_AlphaBand]
        planes = [b.ReadAsArray() for b in colour]
        self.grey = planes[0].astype(np.float32) if len(planes) == 1 else np.mean(planes[:3], axis=0).astype(np.float32)
        if alpha:
            self.mask = alpha[0].ReadAsArray() > 0
        else:
            self.mask = colour[0].GetMaskBand().ReadAsArray() > 0
        self.band_count = dataset.RasterCount
        self.gsd_m = self.geotransform[1]

    def to_pixel(self, easting_m, northing_m):
        """Continuous pixel coordinates (x right, y down; pixel centres at integer + 0.5 are corners' halves)."""
        e0, gsd, _, n0, _, _ = self.geotransform
        return (easting_m - e0) / gsd - 0.5, (n0 - northing_m) / gsd - 0.5

    def to_utm(self, x_px, y_px):
        e0, gsd, _, n0, _, _ = self.geotransform
        return e0 + (x_px + 0.5) * gsd, n0 - (y_px + 0.5) * gsd

    def has_data_at(self, easting_m, northing_m, margin_px=0):
        x, y = self.to_pixel(easting_m, northing_m)
        xi, yi = int(round(x)), int(round(y))
        if xi - margin_px < 0 or yi - margin_px < 0 or xi + margin_px >= self.width or yi + margin_px >= self.height:
            return False
        return bool(np.all(self.mask[yi - margin_px:yi + margin_px + 1, xi - margin_px:xi + margin_px + 1]))


def read_world_file(path):
    with open(path) as f:
        return [float(line) for line in f.read().split()]


def find_checker_saddle(tile, easting_m, northing_m, size_m, search_m=None):
    """Locates the centre (saddle) of a 2x2 checker landmark of side size_m near a predicted position.

    Returns (easting_m, northing_m) of the saddle found, or None when the window leaves the data. The search covers
    +-search_m (default a third of the side) around the prediction: the landmark is found by correlating a synthetic
    checker (both polarities), then refined by cv2.cornerSubPix.
    """
    search_m = size_m / 3.0 if search_m is None else search_m
    half_px = int(math.ceil((search_m + size_m / 2.0) / tile.gsd_m))
    x, y = tile.to_pixel(easting_m, northing_m)
    xi, yi = int(round(x)), int(round(y))
    x0, y0 = max(0, xi - half_px), max(0, yi - half_px)
    x1, y1 = min(tile.width, xi + half_px + 1), min(tile.height, yi + half_px + 1)
    side = max(8, int(round(0.8 * size_m / tile.gsd_m)) // 2 * 2)
    if x1 - x0 <= side or y1 - y0 <= side:
        return None
    valid = tile.mask[y0:y1, x0:x1]
    if valid.mean() < 0.25:
        return None
    window = tile.grey[y0:y1, x0:x1].copy()
    window[~valid] = window[valid].mean()  # no data: neutral grey, so that the strip's edge is no corner
    side = max(8, int(round(0.8 * size_m / tile.gsd_m)) // 2 * 2)
    template = np.ones((side, side), np.float32)
    template[: side // 2, : side // 2] = -1.0
    template[side // 2:, side // 2:] = -1.0
    score = np.abs(cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED))  # either polarity
    # The whole checker must lie on data.
    inside = cv2.erode(valid.astype(np.uint8), np.ones((side, side), np.uint8), anchor=(0, 0))
    score[inside[: score.shape[0], : score.shape[1]] == 0] = 0.0
    _, best, _, loc = cv2.minMaxLoc(score)
    if best < 0.6:
        return None
    corner = np.array([[[loc[0] + side / 2.0 - 0.5, loc[1] + side / 2.0 - 0.5]]], np.float32)
    window8 = cv2.normalize(window, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    win = max(3, side // 6)
    cv2.cornerSubPix(window8, corner, (win, win), (-1, -1),
                     (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 0.01))
    return tile.to_utm(x0 + float(corner[0, 0, 0]), y0 + float(corner[0, 0, 1]))


def overlap_shifts_px(a, b, patch_px=256, min_response=0.2):
    """Local shifts of tile b's content relative to tile a's where both have data.

    The tiles share their GSD; b is resampled onto a's pixel grid (sub-pixel origin offsets included). The common
    area is cut into patch_px squares that both cover entirely; each patch's shift is measured by phase correlation
    (Hanning window). Local patches, because two tiles may overlap in different ways at once: consecutive tiles share
    an image (they must agree), and a return pass over the same seabed is placed by the navigation alone.
    Returns a list of (easting_m, northing_m, dx_px, dy_px, response) for the patches whose correlation peak is
    clear (response >= min_response); empty when the tiles do not overlap.
    """
    if abs(a.gsd_m - b.gsd_m) > 1e-9 * a.gsd_m:
        return []
    # b's top-left corner in a's pixel-corner coordinates: b's pixel i lies on a's pixel i + offset.
    off_x = (b.geotransform[0] - a.geotransform[0]) / a.gsd_m
    off_y = (a.geotransform[3] - b.geotransform[3]) / a.gsd_m
    c0, r0 = max(0, int(math.ceil(off_x))), max(0, int(math.ceil(off_y)))
    c1, r1 = min(a.width, int(math.floor(off_x + b.width))), min(a.height, int(math.floor(off_y + b.height)))
    if c1 - c0 < patch_px or r1 - r0 < patch_px:
        return []
    m = np.float32([[1, 0, c0 - off_x], [0, 1, r0 - off_y]])  # dst (a's grid) -> src (b's pixels)
    size = (c1 - c0, r1 - r0)
    b_grey = cv2.warpAffine(b.grey, m, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    b_mask = cv2.warpAffine(b.mask.astype(np.uint8), m, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP) > 0
    a_grey = a.grey[r0:r1, c0:c1]
    common = a.mask[r0:r1, c0:c1] & b_mask
    window = cv2.createHanningWindow((patch_px, patch_px), cv2.CV_32F)
    shifts = []
    for y in range(0, size[1] - patch_px + 1, patch_px // 2):
        for x in range(0, size[0] - patch_px + 1, patch_px // 2):
            if not common[y:y + patch_px, x:x + patch_px].all():
                continue
            pa = a_grey[y:y + patch_px, x:x + patch_px] - a_grey[y:y + patch_px, x:x + patch_px].mean()
            pb = b_grey[y:y + patch_px, x:x + patch_px] - b_grey[y:y + patch_px, x:x + patch_px].mean()
            (dx, dy), response = cv2.phaseCorrelate(np.ascontiguousarray(pa), np.ascontiguousarray(pb), window)
            if response >= min_response:
                e, n = a.to_utm(c0 + x + patch_px / 2.0, r0 + y + patch_px / 2.0)
                shifts.append((e, n, dx, dy, response))
    return shifts
