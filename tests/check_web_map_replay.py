#!/usr/bin/env python3
"""Checks the live web map in a headless browser during a replay of the sample dive (run by web_map_replay.test).

Chromium opens the page served by web_map_node before the bag plays, and stays on it (no reload) while the chain
writes the tiles: the page's mosaic tiles load with no failed request (the page counts its tile errors), the track
grows between two screenshots, a tile written during the test shows without a reload. After the replay the site
folder opened from disk (file://, no server) shows the mosaic too.
"""
import atexit
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import unittest
import urllib.request

import cv2
import numpy as np
import rospy
import rostest
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from chromium_devtools import HeadlessChromium, screenshot_file  # noqa: E402

BACKGROUND_BGR = np.array([0x24, 0x1a, 0x0b])  # the page's background, #0b1a24
PATIENCE_S = 150.0


def mosaic_fraction(png_path, box=None):
    """Fraction of the screenshot's pixels (in box (x0, y0, x1, y1) if given) that are not the page's background."""
    image = cv2.imread(png_path)
    if box:
        x0, y0, x1, y1 = [int(round(v)) for v in box]
        image = image[max(0, y0):max(0, y1), max(0, x0):max(0, x1)]
    if image.size == 0:
        return 0.0
    far = np.abs(image.astype(int) - BACKGROUND_BGR).sum(axis=2) > 60
    return float(far.mean())


class WebMapReplayTest(unittest.TestCase):

    def page(self):
        return self.browser.evaluate(
            'typeof EXOCET === "undefined" ? "null" : JSON.stringify({stats: EXOCET.stats, zoom: EXOCET.zoom(), title: document.title, '
            'navigations: performance.getEntriesByType("navigation").length, mapZoom: EXOCET.map.getZoom(), '
            'mosaicLoading: EXOCET.mosaicLoading()})')

    def wait_page(self, predicate, what):
        end = time.time() + PATIENCE_S
        while True:
            state = json.loads(self.page())  # null while the page loads
            if state is not None and predicate(state):
                return state
            self.assertLess(time.time(), end, '%s: page %s' % (what, state))
            time.sleep(0.2)

    def test_live_map_in_a_browser(self):
        rospy.init_node('check_web_map_replay')
        bag = rospy.get_param('~bag')
        output_dir = rospy.get_param('~output_dir')
        shots = rospy.get_param('~screenshot_dir')
        os.makedirs(shots, exist_ok=True)
        end = time.time() + 60
        while not rospy.has_param('/web_map/url'):
            self.assertLess(time.time(), end, 'web_map_node gives no URL')
            time.sleep(0.1)
        url = rospy.get_param('/web_map/url')
        self.assertEqual(urllib.request.urlopen(url, timeout=30).status, 200)

        self.browser = HeadlessChromium(url, log_path=os.path.join(shots, 'chromium.log'))
        atexit.register(self.browser.stop)
        self.wait_page(lambda s: s['stats']['connected'], 'the page connects to the live events')

        topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
                  '/nav/altitude', '/nav/datum', '/tf_static']
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics'] + topics,
                                  start_new_session=True)
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))

        # The first tile: its web tiles load in the page.
        first = self.wait_page(lambda s: s['stats']['footprints'] >= 1 and s['stats']['tileLoads'] > 0,
                               'the first tile on the page')
        shot1 = self.browser.screenshot(os.path.join(shots, 'live_1_first_tile.png'))
        # The track grows while the page watches.
        second = self.wait_page(lambda s: s['stats']['trackPoints'] >= first['stats']['trackPoints'] + 20,
                                'the track grows')
        shot2 = self.browser.screenshot(os.path.join(shots, 'live_2_track_grown.png'))
        self.assertGreater(second['stats']['trackPoints'], first['stats']['trackPoints'])
        rospy.loginfo('web map test: track %d -> %d points between the screenshots',
                      first['stats']['trackPoints'], second['stats']['trackPoints'])

        # A tile written during the test: the map is taken to it (no reload) and its web tiles load.
        later = self.wait_page(lambda s: s['stats']['footprints'] > first['stats']['footprints'],
                               'a tile written during the test')
        key = later['stats']['lastTile']
        newest = self.browser.evaluate(
            '(() => { EXOCET.setFollow(false); const b = EXOCET.footprintBounds("%s"); '
            'EXOCET.map.fitBounds(b, {animate: false}); '
            'const p0 = EXOCET.map.latLngToContainerPoint(b.getNorthWest()), '
            'p1 = EXOCET.map.latLngToContainerPoint(b.getSouthEast()); return [p0.x, p0.y, p1.x, p1.y]; })()' % key)
        # Its web tiles are cut at every level (two events, finest first), the view fetches them and has none pending.
        # On a loaded machine the cut comes seconds after the footprint.
        self.wait_page(lambda s: key in s['stats']['cutDoneIds'] and
                       any(r >= s['stats']['cutEventIds'][key] for r in s['stats']['loadedRevs'].values()) and
                       not s['mosaicLoading'], 'the new tile\'s web tiles cut and loaded')
        # The last tiles of the view decode and paint after their load event: a few screenshots, a second apart.
        for attempt in range(10):
            time.sleep(1.0)
            shot3 = self.browser.screenshot(os.path.join(shots, 'live_3_new_tile.png'))
            if mosaic_fraction(shot3, newest) > 0.3:
                break
        settled = json.loads(self.page())
        self.assertEqual(settled['navigations'], 1, 'the page was reloaded')
        self.assertEqual(settled['stats']['pageLoadedAt'], first['stats']['pageLoadedAt'], 'the page was reloaded')
        # Web tiles fetched again after the new tile was cut (their URL carries the event's id): they hold it.
        cut_id = settled['stats']['cutEventIds'][key]
        fresh = [k for k, r in settled['stats']['loadedRevs'].items() if r >= cut_id]
        self.assertTrue(fresh, 'no web tile loaded since %s was cut' % key)
        inside = mosaic_fraction(shot3, newest)
        rospy.loginfo('web map test: the new tile\'s footprint on screen %s, %.0f %% mosaic', newest, 100 * inside)
        self.assertGreater(inside, 0.3, 'the tile written during the test does not show')

        # The end of the dive: the tile writer closes the last mosaic; every tile is on the map.
        end = time.time() + PATIENCE_S
        while player.poll() is None:
            self.assertLess(time.time(), end, 'the bag does not end')
            time.sleep(0.5)
        time.sleep(5.0)  # the chain drains
        rospy.wait_for_service('/tile_writer/flush', timeout=30.0)
        rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        tifs = lambda: sorted(f for f in os.listdir(output_dir) if f.endswith('.tif') and not f.startswith('.'))
        final = self.wait_page(lambda s: s['stats']['footprints'] == len(tifs()) and
                               json.loads(urllib.request.urlopen(url + 'state.json').read())['tiles'] and
                               len(json.loads(urllib.request.urlopen(url + 'state.json').read())['tiles']) ==
                               len(tifs()), 'every tile on the page')
        self.browser.evaluate('(() => { const b = EXOCET.map.getBounds(); let all = null; '
                              'EXOCET.map.eachLayer(l => { if (l.options && l.options.dashArray && l.getBounds) '
                              'all = all ? all.extend(l.getBounds()) : L.latLngBounds(l.getBounds().getSouthWest(), '
                              'l.getBounds().getNorthEast()); }); EXOCET.map.fitBounds(all, {animate: false}); '
                              'return true; })()')
        time.sleep(3.0)
        shot4 = self.browser.screenshot(os.path.join(shots, 'live_4_whole_dive.png'))
        final = json.loads(self.page())
        rospy.loginfo('web map test: %s', final['title'])
        self.assertGreaterEqual(len(tifs()), 3, 'the dive gives several tiles')
        self.assertEqual(final['stats']['tileErrors'], 0, 'failed tile requests: %s' % final['stats']['failedTiles'])
        self.assertGreater(final['stats']['tileLoads'], 10)
        self.assertGreater(final['stats']['usblFixes'], 5)
        self.assertGreater(mosaic_fraction(shot4), 0.05)
        self.browser.stop()

        # After the dive: the site folder opened from disk shows the mosaic without any server.
        site = os.path.join(output_dir, 'web')
        time.sleep(3.0)  # the state files are rewritten every 2 s
        static_shot = os.path.join(shots, 'static_file_site.png')
        title = screenshot_file('file://' + os.path.join(site, 'index.html'), static_shot)
        rospy.loginfo('web map test: file:// page title "%s"', title)
        self.assertIn('tile errors 0', title)
        self.assertNotIn('tiles loaded 0 ', title)
        self.assertGreater(mosaic_fraction(static_shot), 0.05, 'the static site shows no mosaic')
        shutil.rmtree(output_dir, ignore_errors=True)  # passed: the tiles (tens of MB) are not kept


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'web_map_replay', WebMapReplayTest)
