#!/usr/bin/env python3
"""Kills every node of the chain with SIGKILL at two moments of a replay and checks that the dive is mapped anyway
(run by node_kill_replay.test).

The sample out-and-back dive is replayed at 2x with `roslaunch exocet_mosaic replay.launch web:=true`, as a user runs
it, on the test's master, the web map on a fixed free port; the trajectory logger runs beside it
(node_kill_replay.test). The registration, the tile writer, the web map, the fusion and the trajectory logger are each
killed twice (SIGKILL, the pid asked to the node itself through the test's master: never another test's node of the
same name). Checked:
- each node is started again by its launch file (a new pid, answering through the master) and its output goes on
  (after a registration kill, the tile writer bridges the motions missing with the navigation);
- the web map after each kill: serving again on the same port (GET /state.json answers 200), the tiles it had cut
  (its web/tiles.json at the kill) taken over, not cut again, unless their GeoTIFF changed since; an event stream
  open across the kill is closed, and reopened with the killed run's last event id it gets a reset (a page then
  reloads /state.json); it cuts the tiles written after its restart;
- the replay ends by itself (its replay_watcher) once the bag is over, and run_summary.json counts the run's tiles,
  the tile writer's restarts and the frames they lost;
- the tiles: every index from 0 to the last once (one version each), no partial file, no orphan; each opens with
  GDAL in the dive's UTM zone, north-up, with imagery; the surveyed landmarks found where the tiles say, within the
  bound of tiles_replay (3 fused sigmas, at least 5 cm);
- frames lost per tile writer kill, as the restarted writer reports them: at most what it held at that moment (the
  frames not yet on disk in its last /diagnostics before the kill, plus the images published since), and the frame
  numbers of its next tile skip exactly those;
- the trajectory logger's files: appended to after each restart (no second set), rows in time order to the end;
- the web site once the launch has ended: its state.json lists every final GeoTIFF tile (one per index) at its final
  version, the web tiles it lists are on disk, and where only one GeoTIFF tile has imagery its web tiles do too.
Figures merged into out/bench/reliability.json: kills_tried, kills_survived (the web map's kills among them),
tiles_lost, frames_lost_per_kill_max; the details per kill in out/bench/node_kill_replay.json.
"""
import atexit
import csv
import glob
import json
import math
import os
import re
import signal
import socket
import subprocess
import time
import unittest
import urllib.request

import cv2
import dynamic_reconfigure.client
import numpy as np
import rosbag
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import ImageMotion
from nav_msgs.msg import Odometry

from exocet_mosaic.testing import node_pid, utm_to_lat_lon
from exocet_mosaic.reliability import update_reliability, workspace_bench_dir
from exocet_mosaic.tile_analysis import Tile, find_checker_saddle, parse_tile_name

RATE = 2.0
# (node, seconds of dive after the bag's start; the bag holds 87 s): each node twice, one kill every 2.5 to 4 s of wall
# time, the last one 17 s of dive before the bag's end.
KILLS = [('registration', 14.0), ('tile_writer', 20.0), ('web_map', 25.0), ('fusion', 30.0),
         ('trajectory_logger', 36.0), ('registration', 44.0), ('tile_writer', 52.0), ('web_map', 57.0),
         ('fusion', 62.0), ('trajectory_logger', 70.0)]
BACK_TIMEOUT_S = 20.0  # wall seconds for a node to be running again (respawn_delay 1 s, start-up)


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def open_event_stream(port, last_event_id=None):
    """A raw connection to the web map's /events, as a browser's EventSource opens it (Last-Event-ID when resuming)."""
    stream = socket.create_connection(('127.0.0.1', port), timeout=5.0)
    stream.sendall(('GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n%s\r\n' %
                    ('Last-Event-ID: %s\r\n' % last_event_id if last_event_id else '')).encode())
    return stream


def read_stream(stream, marker, timeout_s):
    """What the stream sends until `marker` (bytes) arrives, the server closes it or `timeout_s` passes; and whether
    it was closed."""
    data, deadline = b'', time.time() + timeout_s
    while marker not in data and time.time() < deadline:
        stream.settimeout(max(0.01, deadline - time.time()))
        try:
            chunk = stream.recv(65536)
        except socket.timeout:
            break
        except OSError:  # reset by the killed server
            return data, True
        if not chunk:
            return data, True
        data += chunk
    return data, False


def web_tile_of(lat_deg, lon_deg, z):
    """(x, y, column, row): the XYZ web tile at level z holding a point, and the point's pixel in it."""
    n = 2 ** z
    x = (lon_deg + 180.0) / 360.0 * n
    y = (1.0 - math.asinh(math.tan(math.radians(lat_deg))) / math.pi) / 2.0 * n
    return int(x), int(y), min(255, int((x - int(x)) * 256)), min(255, int((y - int(y)) * 256))


class NodeKillReplayTest(unittest.TestCase):

    def setUp(self):
        rospy.init_node('check_node_kill_replay')
        self.bag = rospy.get_param('~bag')
        self.output = rospy.get_param('~output_dir')
        self.tiles_dir = os.path.join(self.output, 'tiles')
        self.trajectories_dir = os.path.join(self.output, 'trajectories')
        self.site_dir = os.path.join(self.tiles_dir, 'web')
        self.web_port = free_port()  # fixed for the run: a restarted web map must come back on it
        os.makedirs(self.tiles_dir, exist_ok=True)
        stem = self.bag[:-len('.bag')]
        self.landmarks = list(csv.DictReader(open(stem + '.landmarks.csv')))
        with rosbag.Bag(self.bag) as bag:
            self.image_stamps = sorted(m.header.stamp.to_sec() for _, m, _ in bag.read_messages('/camera/camera_info'))
            self.bag_start = bag.get_start_time()
            self.bag_end = bag.get_end_time()
        self.writer_status = None  # (wall, values) of the tile writer's last /diagnostics
        self.sigmas, self.odometry_stamps, self.motion_stamps = [], [], []
        rospy.Subscriber('/diagnostics', DiagnosticArray, self.on_diagnostics, queue_size=100)

        def on_odometry(msg):
            c = msg.pose.covariance
            self.sigmas.append(math.sqrt(max(np.linalg.eigvalsh(np.array([[c[0], c[1]], [c[6], c[7]]])))))
            self.odometry_stamps.append(msg.header.stamp.to_sec())
        rospy.Subscriber('/mosaic/odometry', Odometry, on_odometry, queue_size=1000)
        rospy.Subscriber('/mosaic/motion', ImageMotion, lambda m: self.motion_stamps.append(m.header.stamp.to_sec()),
                         queue_size=1000)

    def on_diagnostics(self, msg):
        for status in msg.status:
            if status.hardware_id.startswith('tile writer'):
                self.writer_status = (time.time(), {kv.key: kv.value for kv in status.values})

    def dive_time(self):
        now = rospy.get_rostime().to_sec()
        return now - self.bag_start if now > 0 else -1.0

    def wait_for(self, condition, timeout_s, step_s=0.1):
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            if condition():
                return True
            time.sleep(step_s)
        return condition()

    def writer_value(self, key, default=None):
        return self.writer_status[1].get(key, default) if self.writer_status else default

    def web_get(self, path):
        """(status, body) of a GET on the web map; (None, None) when it does not answer."""
        try:
            with urllib.request.urlopen('http://127.0.0.1:%d/%s' % (self.web_port, path), timeout=2.0) as reply:
                return reply.status, reply.read()
        except Exception:  # refused, reset, timed out, an HTTP error: not serving
            return None, None

    def web_state(self, timeout_s=10.0):
        """The web map's /state.json, waited for (its server threads are niced below the chain's); None if none."""
        deadline = time.time() + timeout_s
        while True:
            status, body = self.web_get('state.json')
            if status == 200:
                return json.loads(body)
            if time.time() >= deadline:
                return None
            time.sleep(0.2)

    def before_web_map_kill(self):
        """What a page and the restarted node start from: the state a page loaded, the tiles the node had cut (its
        tiles.json on disk), an event stream open across the kill."""
        state = self.web_state()
        self.assertIsNotNone(state, 'the web map serves before its kill')
        before = {'event_id': state['event_id']}
        try:
            with open(os.path.join(self.site_dir, 'tiles.json')) as f:
                before['manifest'] = json.load(f)['tiles']
        except (OSError, ValueError, KeyError):  # none written yet
            before['manifest'] = []
        before['stream'] = open_event_stream(self.web_port)
        greeting, _ = read_stream(before['stream'], b'exocet web map', 10.0)
        self.assertIn(b'exocet web map', greeting, 'the event stream opens before the kill')
        return before

    def after_web_map_restart(self, kill, before):
        """The restarted web map: the stream open across the kill was closed, one resuming from the killed run's id
        is reset, the tiles cut before are taken over (same cut time) unless their GeoTIFF changed since."""
        _, kill['stream_closed'] = read_stream(before['stream'], b'\0', 5.0)
        before['stream'].close()
        stream = open_event_stream(self.web_port, before['event_id'])
        text, _ = read_stream(stream, b'event: reset', 10.0)
        stream.close()
        match = re.search(rb'id: (\S+)\nevent: reset', text)
        kill['stream_reset'] = bool(match) and match.group(1).decode().rsplit('-', 1)[0] != \
            before['event_id'].rsplit('-', 1)[0]
        state = self.web_state()
        cut_now = {t['key']: t['cut_unix_s'] for t in state['tiles']} if state else {}
        unchanged = []
        for t in before['manifest']:
            try:
                st = os.stat(os.path.join(self.tiles_dir, t['file']))
            except OSError:  # replaced by a newer version: cut again
                continue
            if st.st_size == t['size_bytes'] and st.st_mtime_ns == t['mtime_ns']:
                unchanged.append(t)
        kill['tiles_cut_before'] = len(before['manifest'])
        kill['tiles_unchanged'] = len(unchanged)
        kill['tiles_taken_over'] = sum(1 for t in unchanged if t['cut_unix_s'] is not None and
                                       abs((cut_now.get(t['key']) or 0.0) - t['cut_unix_s']) < 0.002)

    def test_every_node_killed_twice(self):
        log = open(os.path.join(self.output, 'replay.log'), 'w')
        launch = subprocess.Popen(['roslaunch', 'exocet_mosaic', 'replay.launch', 'bag:=' + self.bag,
                                   'output_dir:=' + self.tiles_dir, 'rate:=%g' % RATE, 'ground_truth:=true',
                                   'web:=true', 'web_port:=%d' % self.web_port],
                                  stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        atexit.register(lambda: launch.poll() is None and os.killpg(launch.pid, signal.SIGKILL))
        # Smaller mosaics than the preset's: more tiles, more writes to be killed in. On the parameter server through
        # dynamic_reconfigure, so that a restarted writer reads it too.
        self.assertTrue(self.wait_for(lambda: node_pid('tile_writer') is not None, 60.0), 'the tile writer comes up')
        dynamic_reconfigure.client.Client('/tile_writer', timeout=30.0).update_configuration({'frames_per_mosaic': 60})

        kills = []
        for node, at_s in KILLS:
            self.assertTrue(self.wait_for(lambda: self.dive_time() >= at_s, 120.0, 0.02),
                            'the replay reaches %.0f s of dive' % at_s)
            self.wait_for(lambda: node_pid(node) is not None, 10.0)
            pid = node_pid(node)
            self.assertIsNotNone(pid, '%s runs before its kill at %.0f s' % (node, at_s))
            kill = {'node': node, 'dive_s': round(self.dive_time(), 2), 'clock_s': rospy.get_rostime().to_sec(),
                    'pid': pid}
            if node == 'registration':
                bridged = int(self.writer_value('registration gaps bridged by the navigation', '0'))
            if node == 'tile_writer':
                # What it holds: its last report, and the images published since that report's newest image.
                held = int(self.writer_value('frames not on disk yet', '0'))
                newest = float(self.writer_value('newest image stamp (s)', '0'))
                kill['held_at_last_report'] = held
                kill['newest_image_at_last_report_s'] = newest
            if node == 'web_map':
                web_before = self.before_web_map_kill()
            kill['wall'] = time.time()
            os.kill(pid, signal.SIGKILL)
            if node == 'tile_writer':
                published = sum(1 for s in self.image_stamps if newest < s <= kill['clock_s'] + 0.5)
                kill['held_bound'] = held + published

            def running_again():
                # The web map is back once it serves again, on the same port (a browser keeps its URL).
                return node_pid(node) not in (None, pid) and (node != 'web_map' or self.web_get('state.json')[0] == 200)
            back = self.wait_for(running_again, BACK_TIMEOUT_S)
            kill['back'] = back
            kill['back_after_s'] = round(time.time() - kill['wall'], 1)
            if node == 'web_map' and back:
                self.after_web_map_restart(kill, web_before)
            if node == 'registration' and back:
                # Its new sequence has no motion for its first image: the tile writer bridges it with the navigation.
                kill['writer_bridged_the_gap'] = self.wait_for(lambda: int(self.writer_value(
                    'registration gaps bridged by the navigation', '0')) > bridged, 8.0)
            if node == 'tile_writer' and back:
                self.writer_status = None
                reported = self.wait_for(lambda: self.writer_value('run', '').startswith('carried on'), BACK_TIMEOUT_S)
                kill['frames_lost'] = int(self.writer_value('frames lost at the last restart', '-1')) if reported \
                    else None
            kills.append(kill)
            print('node kill replay: %s' % json.dumps(kill))

        # The replay ends by itself once the bag is over and the last tile is written.
        try:
            status = launch.wait(timeout=180.0)
        except subprocess.TimeoutExpired:
            status = None
        log.close()
        self.assertEqual(status, 0, 'replay.launch ends by itself (see %s)' % os.path.join(self.output, 'replay.log'))

        # Each node's output went on after its kills.
        last_dive_s = self.bag_end - self.bag_start
        for kill in kills:
            after = kill['clock_s'] + 5.0
            if kill['node'] == 'registration':
                kill['output_went_on'] = (any(s > after for s in self.motion_stamps) and
                                          kill.get('writer_bridged_the_gap', False))
            elif kill['node'] == 'fusion':
                kill['output_went_on'] = any(s > after for s in self.odometry_stamps)
            elif kill['node'] == 'tile_writer':
                kill['output_went_on'] = kill.get('frames_lost') is not None
        rows = self.check_trajectories(kills)
        tiles, tiles_lost = self.check_tiles(kills)
        web = self.check_web_site(tiles, kills)
        summary = json.load(open(os.path.join(self.tiles_dir, 'run_summary.json')))

        survived = [k for k in kills if k['back'] and k.get('output_went_on')]
        writer_kills = [k for k in kills if k['node'] == 'tile_writer']
        frames_lost = [k['frames_lost'] for k in writer_kills if k.get('frames_lost') is not None]
        figures = {'kills_tried': len(kills), 'kills_survived': len(survived), 'tiles_lost': tiles_lost,
                   'frames_lost_per_kill_max': max(frames_lost) if frames_lost else None}
        bench_dir = workspace_bench_dir(__file__)
        update_reliability(figures, bench_dir)
        per_node = {n: {'tried': sum(k['node'] == n for k in kills), 'survived': sum(k['node'] == n for k in survived)}
                    for n, _ in KILLS}
        with open(os.path.join(bench_dir, 'node_kill_replay.json'), 'w') as f:
            json.dump({'_note': 'node_kill_replay.test: SIGKILL of each node twice during a 2x replay of the sample '
                                'out-and-back dive', 'per_node': per_node, 'kills': kills, 'tiles': len(tiles),
                       'trajectory_rows': rows, 'web_site': web, 'run_summary': summary}, f, indent=2)
        print('node kill replay: %s; per node %s; %d tiles' % (json.dumps(figures), json.dumps(per_node), len(tiles)))

        for kill in kills:
            self.assertTrue(kill['back'], '%s is running again after its kill at %.1f s' %
                            (kill['node'], kill['dive_s']))
            self.assertTrue(kill.get('output_went_on', True), '%s goes on after its kill at %.1f s' %
                            (kill['node'], kill['dive_s']))
        web_kills = [k for k in kills if k['node'] == 'web_map']
        for kill in web_kills:
            self.assertTrue(kill['stream_closed'], 'the killed web map\'s event stream is closed: %s' % kill)
            self.assertTrue(kill['stream_reset'], 'a page resuming from the killed run is reset: %s' % kill)
            self.assertEqual(kill['tiles_taken_over'], kill['tiles_unchanged'],
                             'the restarted web map takes over the tiles already cut: %s' % kill)
            self.assertTrue(kill['cut_after_restart'], 'the restarted web map cuts the tiles written since: %s' % kill)
        self.assertGreater(sum(k['tiles_taken_over'] for k in web_kills), 0, 'a web map is killed with tiles cut')
        for kill in writer_kills:
            self.assertIsNotNone(kill.get('frames_lost'), 'the restarted tile writer reports the frames lost')
            self.assertGreaterEqual(kill['frames_lost'], 0)
            self.assertLessEqual(kill['frames_lost'], kill['held_bound'],
                                 'no more frames lost than the writer held when it was killed: %s' % kill)
        self.assertEqual(summary['restarts'], len(writer_kills), summary)
        self.assertEqual(summary['frames_lost'], sum(frames_lost), summary)
        self.assertEqual(summary['tiles_written'], len(tiles), 'the summary counts the tiles of the whole run')
        self.assertIsNone(summary['reason'])
        self.assertEqual(tiles_lost, 0)
        self.assertGreater(max(self.odometry_stamps) - self.bag_start, last_dive_s - 3.0, 'fused to the end')

    def check_web_site(self, tiles, kills):
        """The site the web map left once the launch has ended (it writes its state files at shutdown): every final
        GeoTIFF at its final version, the web tiles it lists on disk, and web tiles with imagery where only one GeoTIFF
        tile has some (there no other tile's web tiles stand in for a tile never cut). Sets each web map kill's
        cut_after_restart and output_went_on; returns the figures."""
        with open(os.path.join(self.site_dir, 'state.json')) as f:
            state = json.load(f)
        final = {}
        for name in os.listdir(self.tiles_dir):
            if parse_tile_name(name):
                final[re.sub(r'_v\d+$', '', name[:-len('.tif')])] = (parse_tile_name(name)[2], name)
        listed = {t['key']: (t['version'], t['file']) for t in state['tiles']}
        self.assertEqual(listed, final, 'the web map lists every final tile at its final version')
        z = state['web_tiles']['z']
        web_tiles = os.path.join(self.site_dir, 'tiles', str(z))
        missing = [xy for xy in state['web_tiles']['xy']
                   if not os.path.exists(os.path.join(web_tiles, '%d/%d.png' % tuple(xy)))]
        self.assertEqual(missing, [], 'the web tiles of the finest level listed are on disk')

        rng = np.random.default_rng(7)
        alpha, checked, points = {}, 0, 0
        for tile in tiles:
            # Pixels of this tile's imagery, 4 px inside it (the warp's bilinear edge), where no other tile has any.
            inside = cv2.erode(tile.mask.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
            rows, cols = np.nonzero(inside)
            if not len(rows):
                continue
            picked = rng.choice(len(rows), size=min(300, len(rows)), replace=False)
            alone = [(c, r) for r, c in zip(rows[picked], cols[picked])
                     if not any(o is not tile and o.has_data_at(*tile.to_utm(c, r)) for o in tiles)][:15]
            if len(alone) < 5:
                continue
            checked += 1
            for c, r in alone:
                lat, lon = utm_to_lat_lon(*tile.to_utm(c, r), 31, True)
                x, y, col, row = web_tile_of(lat, lon, z)
                path = os.path.join(web_tiles, '%d/%d.png' % (x, y))
                if path not in alpha:
                    image = cv2.imread(path, cv2.IMREAD_UNCHANGED) if os.path.exists(path) else None
                    alpha[path] = image[:, :, 3] if image is not None and image.ndim == 3 and image.shape[2] == 4 \
                        else np.zeros((256, 256), np.uint8)
                self.assertGreater(int(alpha[path][row, col]), 0, '%s: its imagery at pixel (%d, %d) is in web tile '
                                   '%d/%d/%d' % (tile.path, c, r, z, x, y))
                points += 1
        print('node kill replay: web site: %d tiles listed, %d web tiles at level %d; %d tiles with %d points of their '
              'own found in the web tiles' % (len(listed), len(state['web_tiles']['xy']), z, checked, points))
        self.assertGreaterEqual(checked, len(tiles) // 2, 'most tiles have imagery of their own to look for')

        cut_times = [t['cut_unix_s'] for t in state['tiles'] if t['cut_unix_s'] is not None]
        for kill in kills:
            if kill['node'] == 'web_map':
                kill['cut_after_restart'] = any(c > kill['wall'] + kill['back_after_s'] for c in cut_times)
                kill['output_went_on'] = kill['back'] and kill.get('stream_reset', False) and \
                    kill.get('tiles_taken_over') == kill.get('tiles_unchanged') and kill['cut_after_restart']
        return {'tiles_listed': len(listed), 'web_tiles_finest': len(state['web_tiles']['xy']), 'zoom': z,
                'tiles_checked_in_web_tiles': checked, 'points_checked': points}

    def check_trajectories(self, kills):
        """The logger's files after two restarts: one set, appended to, in time order to the end of the dive."""
        names = sorted(os.path.basename(p) for p in glob.glob(os.path.join(self.trajectories_dir, '*')))
        self.assertIn('ground_truth.csv', names)
        self.assertNotIn('ground_truth_2.csv', names, 'a restarted logger appends, it does not start a new set')
        rows = {}
        for name in ('ground_truth.csv', 'navigation.csv'):
            with open(os.path.join(self.trajectories_dir, name)) as f:
                text = f.read()
            self.assertTrue(text.endswith('\n'), name)
            table = list(csv.reader(text.splitlines()))
            width = len(table[0])
            stamps = [float(r[0]) for r in table[1:]]
            self.assertTrue(all(len(r) == width for r in table), '%s: whole rows only' % name)
            self.assertTrue(all(a < b for a, b in zip(stamps, stamps[1:])), '%s: rows in time order' % name)
            self.assertGreater(stamps[-1], self.bag_end - 3.0, '%s: logged to the end of the dive' % name)
            rows[name] = len(stamps)
            for kill in kills:
                if kill['node'] == 'trajectory_logger':
                    kill['output_went_on'] = kill.get('output_went_on', True) and \
                        any(s > kill['clock_s'] + 5.0 for s in stamps)
        return rows

    def check_tiles(self, kills):
        """Every index once, each tile complete and geo-referenced within the bound; returns the tiles and how many
        indices are missing or broken."""
        names = sorted(os.listdir(self.tiles_dir))
        self.assertFalse([n for n in names if '.partial' in n], 'no temporary file is left')
        versions = {}
        for name in names:
            parsed = parse_tile_name(name) if name.endswith('.tif') else None
            if parsed:
                versions.setdefault(parsed[1], []).append(name)
        for name in names:  # no companion without its GeoTIFF
            match = re.match(r'^(tile_\d{4}(_v\d+)?)\.(tfw|kmz)$', name)
            if match:
                self.assertIn(match.group(1) + '.tif', names, '%s has its GeoTIFF' % name)
        indices = sorted(versions)
        self.assertGreaterEqual(len(indices), 4, 'a 435-image dive at 60 images per mosaic gives several tiles')
        duplicates = {i: v for i, v in versions.items() if len(v) > 1}
        self.assertEqual(duplicates, {}, 'one version of each tile')
        missing = sorted(set(range(indices[-1] + 1)) - set(indices))
        tiles, broken = [], 0
        for index in indices:
            path = os.path.join(self.tiles_dir, versions[index][0])
            try:
                tile = Tile(path)
            except Exception as e:  # GDAL cannot open it: a broken tile
                print('node kill replay: %s does not open: %s' % (path, e))
                broken += 1
                continue
            self.assertEqual(tile.epsg, 32631, path)
            self.assertEqual((tile.geotransform[2], tile.geotransform[4]), (0.0, 0.0), 'north-up')
            self.assertGreater(tile.mask.mean(), 0.1, '%s holds imagery' % path)
            tiles.append(tile)
        self.assertEqual(missing, [], 'no tile index is skipped')
        self.assertEqual(broken, 0)

        sigma_m = float(np.median(self.sigmas))
        errors = []
        for mark in self.landmarks:
            e, n, size = float(mark['easting_m']), float(mark['northing_m']), float(mark['size_m'])
            for t in tiles:
                if t.has_data_at(e, n, margin_px=int(size / 2.0 / t.gsd_m)):
                    found = find_checker_saddle(t, e, n, size, search_m=0.5)
                    self.assertIsNotNone(found, 'landmark %s is seen in %s near its surveyed place' % (mark['id'],
                                                                                                      t.path))
                    errors.append(math.hypot(found[0] - e, found[1] - n))
        print('node kill replay: %d tiles, %d landmark sightings, error median %.3f m, max %.3f m; fused 1-sigma '
              'median %.3f m' % (len(tiles), len(errors), float(np.median(errors)) if errors else -1,
                                 max(errors) if errors else -1, sigma_m))
        self.assertGreaterEqual(len(errors), 2)
        self.assertLess(max(errors), max(3.0 * sigma_m, 0.05))

        # Around each tile writer kill: the frames its next tile starts at skip exactly those it reported lost, and
        # the images between the tiles on either side of the gap (lost, or published while it was down) are counted.
        spans = sorted((int(t.metadata['EXOCET_FIRST_FRAME']), int(t.metadata['EXOCET_LAST_FRAME']),
                        float(t.metadata['EXOCET_START_TIME_S']), float(t.metadata['EXOCET_END_TIME_S']))
                       for t in tiles)
        for kill in kills:
            if kill['node'] != 'tile_writer' or kill.get('frames_lost') is None:
                continue
            before = [s for s in spans if s[3] <= kill['clock_s']]
            after = [s for s in spans if s[2] > kill['clock_s']]
            if not before or not after:
                continue
            kill['frame_numbers_skipped'] = after[0][0] - before[-1][1] - 1
            kill['images_without_tile'] = sum(1 for s in self.image_stamps if before[-1][3] < s < after[0][2])
            self.assertGreaterEqual(kill['frame_numbers_skipped'], kill['frames_lost'], kill)
            self.assertGreaterEqual(kill['images_without_tile'], kill['frames_lost'], kill)
        return tiles, len(missing) + broken


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'node_kill_replay', NodeKillReplayTest)
