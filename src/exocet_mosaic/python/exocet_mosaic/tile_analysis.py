"""Reading GeoTIFF tiles back and measuring them against ground truth: the one implementation the tile tests and
bench_tiles share.

Needs python3-gdal and python3-opencv. Coordinates: UTM easting/northing (m); a tile's geotransform is
[E0, gsd, 0, N0, 0, -gsd] (north-up), pixel (col, row) -> E0 + (col + 0.5) * gsd, N0 - (row + 0.5) * gsd at its centre.

Tiles are numbered NAME_NNNN.tif; a tile re-rendered is NAME_NNNN_vK.tif (K >= 2), and the highest version present
of an index is the tile (tile_paths).
"""
import glob
import json
import math
import os
import re

import cv2
import numpy as np
from osgeo import gdal, osr

gdal.UseExceptions()

# Overlaps narrower than this (either side, tile pixels) give no reliable shift.
MIN_OVERLAP_PX = 96
# A checker landmark is taken as found when the normalised correlation with a synthetic checker reaches this.
MIN_CHECKER_SCORE = 0.6
# Colour comparison of overlapping tiles: each tile's data mask is eroded by this many pixels first (the edge pixels
# of a tile are blended with no-data), and a pair needs at least this many common pixels.
OVERLAP_ERODE_PX = 3
MIN_COLOUR_PIXELS = 1000
# A numbered tile: NAME_NNNN.tif, or NAME_NNNN_vK.tif when re-rendered (version K >= 2; no suffix: version 1).
TILE_NAME = re.compile(r'^(?P<prefix>.+)_(?P<index>\d{4,})(?:_v(?P<version>\d+))?\.tif$')


class Tile:
    """A GeoTIFF tile read back with GDAL: grey image (luminance, float), luma (8-bit, OpenCV's BGR -> GRAY), data
    mask, geotransform, EPSG, metadata, index and version (from the file name)."""

    def __init__(self, path):
        dataset = gdal.Open(path)
        self.path = path
        self.name = os.path.basename(path)
        self.width, self.height = dataset.RasterXSize, dataset.RasterYSize
        self.geotransform = dataset.GetGeoTransform()
        self.gsd_m = self.geotransform[1]
        self.epsg = None
        if dataset.GetProjection():
            srs = osr.SpatialReference(wkt=dataset.GetProjection())
            srs.AutoIdentifyEPSG()
            code = srs.GetAuthorityCode(None)
            self.epsg = int(code) if code else None
        self.metadata = dataset.GetMetadata() or {}
        self.compression = (dataset.GetMetadata('IMAGE_STRUCTURE') or {}).get('COMPRESSION')
        self.band_count = dataset.RasterCount
        bands = [dataset.GetRasterBand(i + 1) for i in range(dataset.RasterCount)]
        self.band_types = [gdal.GetColorInterpretationName(b.GetColorInterpretation()) for b in bands]
        colour = [b.ReadAsArray() for b in bands if b.GetColorInterpretation() != gdal.GCI_AlphaBand]
        if len(colour) >= 3:
            # Bands in R, G, B order (GDAL's photometric interpretation): ITU-R BT.601 luminance.
            self.grey = (0.299 * colour[0] + 0.587 * colour[1] + 0.114 * colour[2]).astype(np.float32)
            if all(c.dtype == np.uint8 for c in colour[:3]):
                self.luma = cv2.cvtColor(np.dstack([colour[2], colour[1], colour[0]]), cv2.COLOR_BGR2GRAY)
            else:
                self.luma = np.clip(np.rint(self.grey), 0, 255).astype(np.uint8)
        else:
            self.grey = colour[0].astype(np.float32)
            self.luma = colour[0] if colour[0].dtype == np.uint8 else np.clip(np.rint(self.grey), 0, 255).astype(np.uint8)
        # The alpha band (DEFLATE) or the internal mask (JPEG): GDAL gives both as the first band's mask.
        self.mask = bands[0].GetMaskBand().ReadAsArray() > 0
        self.valid_fraction = float(self.mask.mean())
        self.file_mb = os.path.getsize(path) / 1e6
        self.world_file = os.path.exists(os.path.splitext(path)[0] + '.tfw')
        match = TILE_NAME.match(self.name)
        self.index = int(match.group('index')) if match else -1
        self.version = int(match.group('version') or 1) if match else 1

    def to_pixel(self, easting_m, northing_m):
        """Continuous pixel coordinates (x right, y down), pixel centres on integers (OpenCV's convention)."""
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


def parse_tile_name(name):
    """(prefix, index, version) of a numbered tile's file name (NAME_NNNN.tif: version 1; NAME_NNNN_vK.tif: version
    K), or None for any other file: COG copies (NAME_NNNN.cog.tif), files being written (.partial) and hidden ones."""
    if name.startswith('.') or '.partial' in name or name.endswith('.cog.tif'):
        return None
    match = TILE_NAME.match(name)
    if not match:
        return None
    return match.group('prefix'), int(match.group('index')), int(match.group('version') or 1)


def tile_paths(folder):
    """The numbered tiles of a folder in index order: per index, the highest version present (a re-rendered tile
    NAME_NNNN_vK.tif replaces NAME_NNNN.tif and the lower versions; the writer removes them once it is complete)."""
    best = {}  # (prefix, index) -> (version, path)
    for path in glob.glob(os.path.join(folder, '*.tif')):
        parsed = parse_tile_name(os.path.basename(path))
        if parsed is None:
            continue
        prefix, index, version = parsed
        if (prefix, index) not in best or version > best[(prefix, index)][0]:
            best[(prefix, index)] = (version, path)
    return [best[k][1] for k in sorted(best, key=lambda k: (k[1], k[0]))]


def read_tiles(folder):
    return [Tile(p) for p in tile_paths(folder)]


def read_world_file(path):
    with open(path) as f:
        return [float(line) for line in f.read().split()]


def find_checker_saddle(tile, easting_m, northing_m, size_m, search_m=None, min_score=MIN_CHECKER_SCORE):
    """Locates the centre (saddle) of a 2x2 checker landmark of side size_m near a predicted position.

    Returns (easting_m, northing_m, score) of the saddle found, or None. The search covers +-search_m (default a
    third of the side) around the prediction: a synthetic checker (either polarity) is correlated with the tile
    where the whole checker lies on data (no-data pixels are filled with the mean, so that a strip's edge is no
    corner), then the saddle is refined by cv2.cornerSubPix; a refinement that runs further than its window is
    refused (it left the saddle).
    """
    search_m = size_m / 3.0 if search_m is None else search_m
    half_px = int(math.ceil((search_m + size_m / 2.0) / tile.gsd_m))
    x, y = tile.to_pixel(easting_m, northing_m)
    xi, yi = int(round(x)), int(round(y))
    x0, y0 = max(0, xi - half_px), max(0, yi - half_px)
    x1, y1 = min(tile.width, xi + half_px + 1), min(tile.height, yi + half_px + 1)
    side = max(8, int(round(0.8 * size_m / tile.gsd_m)) // 2 * 2)  # the inner 80 % of the board
    if x1 - x0 <= side or y1 - y0 <= side:
        return None
    valid = tile.mask[y0:y1, x0:x1]
    if valid.mean() < 0.25:
        return None
    window = tile.grey[y0:y1, x0:x1].copy()
    window[~valid] = window[valid].mean()
    template = np.ones((side, side), np.float32)
    template[: side // 2, : side // 2] = -1.0
    template[side // 2:, side // 2:] = -1.0
    score = np.abs(cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED))  # either polarity
    inside = cv2.erode(valid.astype(np.uint8), np.ones((side, side), np.uint8), anchor=(0, 0))
    score[inside[: score.shape[0], : score.shape[1]] == 0] = 0.0
    _, best, _, loc = cv2.minMaxLoc(score)
    if best < min_score:
        return None
    start = np.array([[[loc[0] + side / 2.0 - 0.5, loc[1] + side / 2.0 - 0.5]]], np.float32)
    window8 = cv2.normalize(window, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    win = max(3, side // 6)
    corner = cv2.cornerSubPix(window8, start.copy(), (win, win), (-1, -1),
                              (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 0.01))
    if math.hypot(corner[0, 0, 0] - start[0, 0, 0], corner[0, 0, 1] - start[0, 0, 1]) > 2.0 * win:
        return None
    e, n = tile.to_utm(x0 + float(corner[0, 0, 0]), y0 + float(corner[0, 0, 1]))
    return e, n, float(best)


def ambiguous_landmarks(marks, search_m):
    """Ids of the landmarks closer to another than the search window plus a board: they cannot be told apart."""
    return {m['id'] for m in marks for o in marks if o is not m and math.hypot(
        m['easting_m'] - o['easting_m'], m['northing_m'] - o['northing_m']) < search_m + max(m['size_m'], o['size_m'])}


def landmark_observations(tiles, marks, search_m=0.25):
    """Every sighting expected of a surveyed landmark (the whole board inside a tile's data), found or not.

    marks: dicts with id, easting_m, northing_m, size_m. Returns dicts with tile, landmark, found, and when found
    error_m, de_m, dn_m (found minus surveyed) and score. Landmarks that cannot be told apart are left out.
    """
    ambiguous = ambiguous_landmarks(marks, search_m)
    observations = []
    for tile in tiles:
        for mark in marks:
            if mark['id'] in ambiguous:
                continue
            half_px = int(math.ceil(mark['size_m'] / 2.0 / tile.gsd_m))
            if not tile.has_data_at(mark['easting_m'], mark['northing_m'], margin_px=half_px):
                continue
            found = find_checker_saddle(tile, mark['easting_m'], mark['northing_m'], mark['size_m'], search_m=search_m)
            obs = {'tile': tile.name, 'landmark': mark['id'], 'found': found is not None}
            if found:
                de, dn = found[0] - mark['easting_m'], found[1] - mark['northing_m']
                obs.update({'error_m': math.hypot(de, dn), 'de_m': de, 'dn_m': dn, 'score': found[2]})
            observations.append(obs)
    return observations


def resample_pair(a, b):
    """Both tiles on the grid of a, cropped to their overlap's bounding box; None when they do not overlap."""
    ga, gb = a.geotransform, b.geotransform
    # Pixel of a -> continuous pixel of b (same GSD; origins may differ by a fraction of a pixel).
    du = (ga[0] - gb[0]) / gb[1]
    dv = (ga[3] - gb[3]) / gb[5]
    c0, c1 = max(0, int(math.floor(-du))), min(a.width, int(math.ceil(b.width - du)))
    r0, r1 = max(0, int(math.floor(-dv))), min(a.height, int(math.ceil(b.height - dv)))
    if c1 - c0 < MIN_OVERLAP_PX or r1 - r0 < MIN_OVERLAP_PX:
        return None
    cols, rows = np.meshgrid(np.arange(c0, c1, dtype=np.float32) + np.float32(du),
                             np.arange(r0, r1, dtype=np.float32) + np.float32(dv))
    b_grey = cv2.remap(b.grey, cols, rows, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    b_mask = cv2.remap(b.mask.astype(np.uint8), cols, rows, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                       borderValue=0) > 0
    a_grey = a.grey[r0:r1, c0:c1]
    both = a.mask[r0:r1, c0:c1] & b_mask
    ys, xs = np.nonzero(both)
    if len(xs) == 0 or xs.max() - xs.min() < MIN_OVERLAP_PX or ys.max() - ys.min() < MIN_OVERLAP_PX:
        return None
    box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    return a_grey[box], b_grey[box], both[box]


def pair_shift(a, b, patch_px=256, min_response=0.1):
    """Shift (tile px) of tile b relative to tile a on their common grid.

    The overlap is cut into windowed patches wholly inside both masks (a mask edge would pull the shift to zero),
    each band-passed (the lamp's shading differs between passes, the seabed's texture does not) and
    phase-correlated; the shift is the median of the patches whose peak is clear. None when the tiles do not
    overlap; shift_px None when no two patches correlate (one patch alone may be a chance peak).
    """
    pair = resample_pair(a, b)
    if pair is None:
        return None
    ia, ib, both = pair
    f = max(1, int(round(0.004 / a.gsd_m)))  # work near 4 mm/px: the seabed's texture, not the pixel noise
    if f > 1:
        ia = cv2.resize(ia, None, fx=1.0 / f, fy=1.0 / f, interpolation=cv2.INTER_AREA)
        ib = cv2.resize(ib, None, fx=1.0 / f, fy=1.0 / f, interpolation=cv2.INTER_AREA)
        both = cv2.resize(both.astype(np.uint8), (ia.shape[1], ia.shape[0]), interpolation=cv2.INTER_NEAREST) > 0
    ia = (ia - cv2.GaussianBlur(ia, (0, 0), 12)).astype(np.float64)
    ib = (ib - cv2.GaussianBlur(ib, (0, 0), 12)).astype(np.float64)
    h, w = both.shape
    # Overlaps of adjacent lines are strips: smaller patches there (a patch holds shifts up to a quarter of it).
    while True:
        window = cv2.createHanningWindow((patch_px, patch_px), cv2.CV_64F)
        patches = []
        for r in range(0, h - patch_px + 1, patch_px // 2):
            for c in range(0, w - patch_px + 1, patch_px // 2):
                if not both[r:r + patch_px, c:c + patch_px].all():
                    continue
                (dx, dy), response = cv2.phaseCorrelate(ia[r:r + patch_px, c:c + patch_px],
                                                        ib[r:r + patch_px, c:c + patch_px], window)
                patches.append((dx, dy, response, c + 0.5 * patch_px, r + 0.5 * patch_px))
        if len(patches) >= 2 or patch_px <= 64:
            break
        patch_px //= 2
    out = {'patches': len(patches), 'patch_px': patch_px * f, 'overlap_px': int(both.sum()) * f * f, 'scale': f}
    good = [p for p in patches if p[2] >= min_response]
    out['patches_correlated'] = len(good)
    if len(good) < 2:
        out.update({'shift_px': None, 'dx_px': None, 'dy_px': None})
        return out
    # The median over patches: the shift of most of the overlap. The spread says how much it varies across the
    # overlap (rotation or scale between the tiles, not a translation).
    mdx, mdy = float(np.median([p[0] for p in good])), float(np.median([p[1] for p in good]))
    dev = [math.hypot(p[0] - mdx, p[1] - mdy) for p in good]
    out.update({'dx_px': mdx * f, 'dy_px': mdy * f, 'shift_px': math.hypot(mdx, mdy) * f,
                'patches_agreeing_2px': sum(1 for d in dev if d * f < 2.0),
                'response_median': float(np.median([p[2] for p in good])),
                'spread_px': float(np.median(dev)) * f,
                'patch_shift_p95_px': float(np.percentile([math.hypot(p[0], p[1]) for p in good], 95)) * f})
    out.update(shift_field(good, f))
    return out


def shift_field(patches, f):
    """What the patch shifts say about the pair: a translation, or a rotation / scale between the tiles (a shift that
    grows across the overlap). Least squares of d = t + [s -r; r s] (x - mean x) over the patches (x: patch centre);
    r in mrad, s in per mille, t in px; the residual is what neither explains (noise, perspective, blending)."""
    if len(patches) < 3:
        return {}
    x = np.array([[p[3], p[4]] for p in patches], dtype=np.float64)
    d = np.array([[p[0], p[1]] for p in patches], dtype=np.float64)
    x -= x.mean(axis=0)
    if np.ptp(x[:, 0]) + np.ptp(x[:, 1]) < 1e-6:
        return {}
    a = np.zeros((2 * len(patches), 4))
    a[0::2] = np.c_[x[:, 0], -x[:, 1], np.ones(len(x)), np.zeros(len(x))]
    a[1::2] = np.c_[x[:, 1], x[:, 0], np.zeros(len(x)), np.ones(len(x))]
    sol, *_ = np.linalg.lstsq(a, d.reshape(-1), rcond=None)
    res = d.reshape(-1) - a @ sol
    return {'field_translation_px': math.hypot(sol[2], sol[3]) * f, 'field_rotation_mrad': sol[1] * 1e3,
            'field_scale_permille': sol[0] * 1e3,
            'field_residual_px': float(np.sqrt(np.mean(res[0::2] ** 2 + res[1::2] ** 2))) * f}


def overlapping_pair_shifts(tiles):
    """pair_shift of every pair of tiles in the same CRS and GSD that overlap, with a (first) and b (second) names
    and whether they are consecutive (indices one apart: they share an image)."""
    pairs = []
    for i in range(len(tiles)):
        for j in range(i + 1, len(tiles)):
            a, b = tiles[i], tiles[j]
            if a.epsg != b.epsg or abs(a.gsd_m - b.gsd_m) > 1e-9 * a.gsd_m:
                continue
            s = pair_shift(a, b, patch_px=256 if a.gsd_m < 0.004 else 192)
            if s is None:
                continue
            s.update({'a': a.name, 'b': b.name, 'consecutive': b.index - a.index == 1})
            pairs.append(s)
    return pairs


# ---------------------------------------------------------------------------------------------------------------
# Colour (brightness) agreement of overlapping tiles.

def pair_colour_difference(a, b, dx_px, dy_px, erode_px=OVERLAP_ERODE_PX, min_pixels=MIN_COLOUR_PIXELS):
    """Luma of tile b against tile a where both have data, after aligning b onto a by the pair's measured shift.

    dx_px, dy_px: the shift of b relative to a on a's grid (pair_shift's dx_px, dy_px): b is sampled at a's pixel
    plus the offset between the tiles' origins plus the shift, rounded to whole pixels (no interpolation: the grey
    levels compared are the tiles' own). Both data masks are eroded by erode_px first (edge pixels are blended with
    no-data). Luma: 8-bit, OpenCV's BGR -> GRAY (Tile.luma).

    Returns None when fewer than min_pixels pixels are common; else a dict: level_step_grey (mean luma of a minus
    mean luma of b on the common pixels, signed), abs_diff_hist (256 counts of |luma a - luma b|, numpy int64),
    abs_diff_median_grey, pixels (common pixel count), offset_px ((col, row) offset applied to b).
    """
    ga, gb = a.geotransform, b.geotransform
    du = (ga[0] - gb[0]) / gb[1] + dx_px  # a's column + du = b's column
    dv = (ga[3] - gb[3]) / gb[5] + dy_px
    ou, ov = int(round(du)), int(round(dv))
    # a's pixels whose counterpart in b exists: a column range and a row range.
    c0, c1 = max(0, -ou), min(a.width, b.width - ou)
    r0, r1 = max(0, -ov), min(a.height, b.height - ov)
    if c1 <= c0 or r1 <= r0:
        return None
    kernel = np.ones((2 * erode_px + 1, 2 * erode_px + 1), np.uint8) if erode_px > 0 else None

    def eroded(mask, rows, cols):
        """The mask inside rows x cols, eroded; the tile's border counts as no-data, the rest of the tile around
        the crop as it is (a margin of erode_px is eroded with it)."""
        if kernel is None:
            return mask[rows, cols]
        r_lo, r_hi = max(0, rows.start - erode_px), min(mask.shape[0], rows.stop + erode_px)
        c_lo, c_hi = max(0, cols.start - erode_px), min(mask.shape[1], cols.stop + erode_px)
        window = cv2.erode(mask[r_lo:r_hi, c_lo:c_hi].astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT,
                           borderValue=0)
        return window[rows.start - r_lo:rows.stop - r_lo, cols.start - c_lo:cols.stop - c_lo] > 0

    rows_a, cols_a = slice(r0, r1), slice(c0, c1)
    rows_b, cols_b = slice(r0 + ov, r1 + ov), slice(c0 + ou, c1 + ou)
    both = eroded(a.mask, rows_a, cols_a) & eroded(b.mask, rows_b, cols_b)
    pixels = int(both.sum())
    if pixels < min_pixels:
        return None
    la = a.luma[rows_a, cols_a][both].astype(np.int16)
    lb = b.luma[rows_b, cols_b][both].astype(np.int16)
    hist = np.bincount(np.abs(la - lb), minlength=256).astype(np.int64)
    return {'level_step_grey': float(la.mean() - lb.mean()), 'abs_diff_hist': hist,
            'abs_diff_median_grey': histogram_median(hist), 'pixels': pixels, 'offset_px': (ou, ov)}


def histogram_median(hist):
    """Median of the integer values counted in hist (hist[v]: how many times v), as numpy.median would give it
    (the mean of the two middle values for an even count); None when empty."""
    n = int(hist.sum())
    if n == 0:
        return None
    cum = np.cumsum(hist)
    lower = int(np.searchsorted(cum, (n - 1) // 2 + 1))  # value of rank (n - 1) // 2 (0-based)
    upper = int(np.searchsorted(cum, n // 2 + 1))        # value of rank n // 2
    return 0.5 * (lower + upper)


def overlap_colour_figures(tiles, pairs, erode_px=OVERLAP_ERODE_PX):
    """Brightness agreement of every overlapping pair of tiles (consecutive and others), each aligned by its measured
    shift (pairs: overlapping_pair_shifts; pairs without a shift are left out).

    Returns overlap_level_step_max_grey (max over pairs of |mean luma a - mean luma b| on their common pixels),
    overlap_abs_diff_median_grey (median of |luma a - luma b| pooled over the common pixels of all pairs),
    overlap_colour_pairs (pairs measured), overlap_colour_pixels, and per pair (a, b, level_step_grey,
    abs_diff_median_grey, pixels) in overlap_colour_per_pair. Figures None when no pair could be measured.
    """
    by_name = {t.name: t for t in tiles}
    pooled = np.zeros(256, np.int64)
    steps, per_pair = [], []
    for p in pairs:
        if p.get('dx_px') is None or p.get('dy_px') is None or p['a'] not in by_name or p['b'] not in by_name:
            continue
        d = pair_colour_difference(by_name[p['a']], by_name[p['b']], p['dx_px'], p['dy_px'], erode_px=erode_px)
        if d is None:
            continue
        pooled += d['abs_diff_hist']
        steps.append(abs(d['level_step_grey']))
        per_pair.append({'a': p['a'], 'b': p['b'], 'level_step_grey': d['level_step_grey'],
                         'abs_diff_median_grey': d['abs_diff_median_grey'], 'pixels': d['pixels']})
    return {'overlap_level_step_max_grey': max(steps) if steps else None,
            'overlap_abs_diff_median_grey': histogram_median(pooled), 'overlap_colour_pairs': len(steps),
            'overlap_colour_pixels': int(pooled.sum()), 'overlap_colour_per_pair': per_pair}


def read_graph_sigmas(path):
    """The pose graph's 1-sigma at its key frames, from the tile writer's graph_corrections.csv (columns
    east_sigma_m, north_sigma_m, east_north_correlation; rows without them are skipped). Returns (stamps_s, covariances
    (n, 2, 2) m^2), both empty when the file has no sigma."""
    stamps, covariances = [], []
    if not os.path.exists(path):
        return np.zeros(0), np.zeros((0, 2, 2))
    with open(path) as f:
        header = f.readline().strip().split(',')
        if 'east_sigma_m' not in header:
            return np.zeros(0), np.zeros((0, 2, 2))
        col = {name: i for i, name in enumerate(header)}
        for line in f:
            fields = line.strip().split(',')
            try:
                se, sn = float(fields[col['east_sigma_m']]), float(fields[col['north_sigma_m']])
                rho = float(fields[col['east_north_correlation']])
                stamps.append(float(fields[col['stamp_s']]))
            except (ValueError, IndexError):
                continue
            covariances.append([[se * se, rho * se * sn], [rho * se * sn, sn * sn]])
    return np.array(stamps), np.array(covariances).reshape(-1, 2, 2)


def recorded_image_centres(records_dir):
    """(stamp_s, easting_m, northing_m) of the centre of every image the tile writer kept (its tile_*.json records),
    where its record places it."""
    centres = []
    for path in sorted(glob.glob(os.path.join(records_dir, 'tile_*.json'))):
        with open(path) as f:
            record = json.load(f)
        origin = record['ground_origin_en_m']
        for image in record['images']:
            h = np.array(image['ground_from_px'], float).reshape(3, 3)
            p = h @ np.array([0.5 * image['width_px'], 0.5 * image['height_px'], 1.0])
            centres.append((image['stamp_s'], origin[0] + p[0] / p[2], origin[1] + p[1] / p[2]))
    return np.array(centres).reshape(-1, 3)


def graph_sigma_check(observations, marks, records_dir):
    """The landmark errors of a dive's tiles against the pose graph's own 1-sigma where they lie: each found landmark
    takes the marginal covariance of the key frame nearest in time to the kept image whose centre is nearest to it.

    Returns None without sigmas, else a dict: landmarks (checked), radial_median_m and radial_min_m (sqrt(sigma_E^2 +
    sigma_N^2)), within_radial_sigma_fraction (error <= that; 0.63 for errors drawn from an isotropic Gaussian of that
    covariance), mahalanobis_median / _p95 (sqrt(e^T C^-1 e): 1.18 / 2.45 for such errors), within_1sigma_fraction
    (Mahalanobis <= 1; 0.39 for such errors). The errors of nearby landmarks share the graph's offset there, so they
    are not independent draws."""
    stamps, covariances = read_graph_sigmas(os.path.join(records_dir, 'graph_corrections.csv'))
    centres = recorded_image_centres(records_dir)
    if len(stamps) == 0 or len(centres) == 0:
        return None
    by_id = {m['id']: m for m in marks}
    radial, within_radial, mahalanobis = [], [], []
    for o in observations:
        if not o.get('found') or o['landmark'] not in by_id:
            continue
        mark = by_id[o['landmark']]
        nearest = int(np.argmin(np.hypot(centres[:, 1] - mark['easting_m'], centres[:, 2] - mark['northing_m'])))
        k = int(np.argmin(np.abs(stamps - centres[nearest, 0])))
        c = covariances[k]
        e = np.array([o['de_m'], o['dn_m']])
        r = math.sqrt(c[0, 0] + c[1, 1])
        radial.append(r)
        within_radial.append(o['error_m'] <= r)
        mahalanobis.append(math.sqrt(float(e @ np.linalg.solve(c, e))))
    if not radial:
        return None
    return {'landmarks': len(radial), 'radial_median_m': float(np.median(radial)),
            'radial_min_m': float(np.min(radial)),
            'within_radial_sigma_fraction': float(np.mean(within_radial)),
            'mahalanobis_median': float(np.median(mahalanobis)),
            'mahalanobis_p95': float(np.percentile(mahalanobis, 95)),
            'within_1sigma_fraction': float(np.mean(np.array(mahalanobis) <= 1.0))}
