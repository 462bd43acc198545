#!/usr/bin/env python3
"""Checks web_map_node over HTTP (run by web_map_node.test): a Tile message for a GeoTIFF written here is cut into
web tiles that the server serves and the event stream announces; the fused odometry, with the datum, becomes the
track; the diagnostics count what happened."""
import http.client
import json
import os
import threading
import time
import unittest
import urllib.error
import urllib.request

import numpy as np
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import GeoDatum, Tile
from nav_msgs.msg import Odometry
from osgeo import gdal, osr
from sensor_msgs.msg import NavSatFix

ORIGIN_E, ORIGIN_N = 734406.0, 4772749.0  # near the sample dive, UTM 31 N
GSD_M = 0.005
PATIENCE_S = 90.0  # generous: a slow machine only waits longer


def write_geotiff(path, east_offset_m, colour):
    width, height = 300, 200
    ds = gdal.GetDriverByName('GTiff').Create(path + '.partial', width, height, 4, gdal.GDT_Byte,
                                              ['COMPRESS=DEFLATE', 'ALPHA=YES'])
    ds.SetGeoTransform([ORIGIN_E + east_offset_m, GSD_M, 0, ORIGIN_N, 0, -GSD_M])
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32631)
    ds.SetProjection(srs.ExportToWkt())
    ds.SetMetadataItem('EXOCET_FRAMES_COMPOSED', '12')
    for band, value in enumerate(colour):
        ds.GetRasterBand(band + 1).WriteArray(np.full((height, width), value, np.uint8))
    alpha = np.full((height, width), 255, np.uint8)
    alpha[:, :20] = 0
    ds.GetRasterBand(4).WriteArray(alpha)
    ds.GetRasterBand(4).SetColorInterpretation(gdal.GCI_AlphaBand)
    ds = None
    os.rename(path + '.partial', path)  # as the tile writer: whole, then announced


class EventReader(threading.Thread):
    """Reads the server's /events stream and keeps every (type, data) event."""

    def __init__(self, host, port):
        super().__init__(daemon=True)
        self.events = []
        self.connection = http.client.HTTPConnection(host, port, timeout=PATIENCE_S)
        self.connection.request('GET', '/events')
        self.response = self.connection.getresponse()
        self.status = self.response.status

    def run(self):
        kind = None
        try:
            while True:
                line = self.response.fp.readline().decode('utf-8')
                if not line:
                    return
                line = line.rstrip('\r\n')
                if line.startswith('event: '):
                    kind = line[7:]
                elif line.startswith('data: ') and kind:
                    self.events.append((kind, json.loads(line[6:])))
                    kind = None
        except Exception:  # the node shuts down
            return

    def wait_for(self, predicate, what):
        end = time.time() + PATIENCE_S
        while time.time() < end:
            found = [data for kind, data in list(self.events) if predicate(kind, data)]
            if found:
                return found[-1]
            time.sleep(0.05)
        raise AssertionError('no event %s in %.0f s; got %s' % (what, PATIENCE_S, [k for k, _ in self.events]))


def get(url):
    try:
        with urllib.request.urlopen(url, timeout=30) as r:
            return r.status, r.headers, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.headers, e.read()


class WebMapNodeTest(unittest.TestCase):

    def test_tiles_track_and_events(self):
        rospy.init_node('web_map_node_check')
        tiles_dir = rospy.get_param('~tiles_dir')
        end = time.time() + PATIENCE_S
        while not rospy.has_param('/web_map/url') and time.time() < end:
            time.sleep(0.1)
        url = rospy.get_param('/web_map/url')
        self.assertTrue(url.startswith('http://127.0.0.1:'), url)
        host, port = url[7:-1].split(':')
        diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, diagnostics.append)
        tiles = rospy.Publisher('/mosaic/tile', Tile, queue_size=10, latch=True)
        odometry = rospy.Publisher('/mosaic/odometry', Odometry, queue_size=100)
        datum_pub = rospy.Publisher('/mosaic/datum', GeoDatum, queue_size=1, latch=True)
        usbl = rospy.Publisher('/nav/usbl', NavSatFix, queue_size=10)

        status, _, page = get(url)
        self.assertEqual(status, 200)
        self.assertIn(b'leaflet/leaflet.js', page)
        self.assertEqual(get(url + 'leaflet/leaflet.js')[0], 200)
        events = EventReader(host, int(port))
        self.assertEqual(events.status, 200)
        events.start()

        # The datum, then the vehicle moving east along the tile, and a USBL fix.
        datum = GeoDatum(frame_id='utm', utm_zone=31, northern_hemisphere=True, epsg=32631)
        datum_pub.publish(datum)
        end = time.time() + PATIENCE_S
        while odometry.get_num_connections() == 0 or tiles.get_num_connections() == 0:
            self.assertLess(time.time(), end, 'web_map_node does not subscribe')
            time.sleep(0.1)
        time.sleep(0.5)
        for i in range(30):
            msg = Odometry()
            msg.header.stamp = rospy.Time(1700000000 + i * 0.2)
            msg.header.frame_id = 'utm'
            msg.pose.pose.position.x = ORIGIN_E + 0.15 * i  # beyond ~track_min_spacing_m (0.1 m)
            msg.pose.pose.position.y = ORIGIN_N - 0.5
            msg.pose.pose.orientation.w = 1.0
            odometry.publish(msg)
            time.sleep(0.01)
        fix = NavSatFix()
        fix.header.stamp = rospy.Time(1700000001)
        fix.latitude, fix.longitude = 43.0712, 5.879
        fix.position_covariance = [0.25, 0, 0, 0, 0.25, 0, 0, 0, 1]
        fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        usbl.publish(fix)

        # A tile written, then announced as the tile writer does.
        path = os.path.join(tiles_dir, 'tile_0000.tif')
        write_geotiff(path, 0.0, (200, 40, 40))
        tiles.publish(Tile(index=0, version=1, geotiff_path=path, epsg=32631, utm_zone=31, gsd_m=GSD_M))
        tile_event = events.wait_for(lambda k, d: k == 'tile' and d['key'] == 'tile_0000', 'tile tile_0000')
        self.assertEqual(tile_event['metadata']['frames_composed'], 12)
        # The finest level announced first, then the coarser levels (none here: the tile fits in one web tile).
        cut = events.wait_for(lambda k, d: k == 'webtiles' and d['key'] == 'tile_0000' and d['levels'] == 'finest',
                              'webtiles of tile_0000, finest level')
        events.wait_for(lambda k, d: k == 'webtiles' and d['key'] == 'tile_0000' and d['levels'] == 'coarser',
                        'webtiles of tile_0000, coarser levels')
        self.assertEqual(cut['zoom']['max'], 23)
        self.assertTrue(cut['written'])
        for z, x, y in cut['written']:
            status, headers, body = get('%stiles/%d/%d/%d.png' % (url, z, x, y))
            self.assertEqual(status, 200, (z, x, y))
            self.assertEqual(headers['Content-Type'], 'image/png')
            self.assertTrue(body.startswith(b'\x89PNG'))
        z, x, y = cut['written'][0]
        self.assertEqual(get('%stiles/%d/%d/%d.png' % (url, z, x + 1000, y))[0], 404)
        self.assertEqual(get(url + 'tiles/../../etc/passwd')[0] in (400, 404), True)

        # The track and the fix in the state and in the events.
        events.wait_for(lambda k, d: k == 'track' and d['points'], 'track')
        events.wait_for(lambda k, d: k == 'usbl', 'usbl')
        end = time.time() + PATIENCE_S
        while True:
            state = json.loads(get(url + 'state.json')[2])
            if len(state["track"]) == 30 and state['usbl'] and state['tiles']:
                break
            self.assertLess(time.time(), end, 'state.json: %d track points' % len(state['track']))
            time.sleep(0.1)
        lat, lon = state['track'][0][0], state['track'][0][1]
        self.assertAlmostEqual(lat, 43.0712, delta=0.001)
        self.assertAlmostEqual(lon, 5.879, delta=0.001)
        self.assertEqual(state['datum']['utm_zone'], 31)
        self.assertEqual(state['web_tiles']['z'], 23)

        # A second tile: announced too, its web tiles served.
        path = os.path.join(tiles_dir, 'tile_0001.tif')
        write_geotiff(path, 1.0, (40, 200, 40))
        tiles.publish(Tile(index=1, version=1, geotiff_path=path, epsg=32631, utm_zone=31, gsd_m=GSD_M))
        cut = events.wait_for(lambda k, d: k == 'webtiles' and d['key'] == 'tile_0001' and d['levels'] == 'finest',
                              'webtiles of tile_0001, finest level')
        self.assertTrue(cut['written'])
        for z, x, y in cut['written']:
            self.assertEqual(get('%stiles/%d/%d/%d.png' % (url, z, x, y))[0], 200)
        # A tile message for a file GDAL cannot read: reported, the node goes on.
        bad = os.path.join(tiles_dir, 'tile_0002.tif')
        with open(bad, 'w') as f:
            f.write('not a GeoTIFF')
        tiles.publish(Tile(index=2, version=1, geotiff_path=bad))

        end = time.time() + PATIENCE_S
        while True:
            values = {}
            for array in list(diagnostics):
                for s in array.status:
                    if s.name.endswith('web map'):
                        values = {kv.key: kv.value for kv in s.values}
                        level = s.level
            if values.get('errors') == '1' and int(values.get('GeoTIFF tiles cut', 0)) >= 2:
                break
            self.assertLess(time.time(), end, 'diagnostics: %s' % values)
            time.sleep(0.2)
        self.assertEqual(level, 1)  # WARN: one GeoTIFF could not be read
        self.assertIn('tile_0002.tif', values['last error'])
        self.assertGreaterEqual(int(values['web tiles cut']), len(cut['written']))
        self.assertGreaterEqual(int(values['live event streams']), 1)
        self.assertEqual(get(url + 'index.html')[0], 200)
        # The site on disk: what a browser opens after the dive.
        for name in ('index.html', 'state.js', 'state.json', 'tiles.json', 'track.json'):
            self.assertTrue(os.path.exists(os.path.join(tiles_dir, 'web', name)), name)


if __name__ == '__main__':
    rostest.rosrun('exocet_web', 'web_map_node', WebMapNodeTest)
