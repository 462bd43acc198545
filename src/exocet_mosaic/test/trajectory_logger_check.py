#!/usr/bin/env python3
"""Checks trajectory_logger against synthetic messages with known values (run by trajectory_logger.test).

The test runs on sim time and publishes /clock itself, so that the arrival time of each USBL fix is known. It starts
every logger it checks as a child process (each with its own topics and a fresh folder), because some cases need
several loggers, bad parameters or a kill. All waits are on the wall clock: the sim clock only moves when we say.
"""
import csv
import math
import os
import shutil
import signal
import subprocess
import tempfile
import time
import unittest

import roslib.packages
import rospy
import rostest
from exocet_mosaic.testing import lat_lon_to_utm, stamp_text
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import GeoDatum
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import NavSatFix, NavSatStatus

PKG = 'exocet_mosaic'
T0_S = 1700000000  # sim time of the tests, whole seconds since the epoch

GT_COLUMNS = ['stamp_s', 'easting_m', 'northing_m', 'up_m', 'roll_deg', 'pitch_deg', 'yaw_deg']
NAV_COLUMNS = GT_COLUMNS + ['horizontal_sigma_m', 'up_sigma_m']
USBL_COLUMNS = ['stamp_s', 'arrival_s', 'latitude_deg', 'longitude_deg', 'easting_m', 'northing_m',
                'horizontal_sigma_m']


def quaternion(roll_deg, pitch_deg, yaw_deg):
    """x, y, z, w of Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (math.radians(v) / 2.0 for v in (roll_deg, pitch_deg, yaw_deg))
    return (math.sin(r) * math.cos(p) * math.cos(y) - math.cos(r) * math.sin(p) * math.sin(y),
            math.cos(r) * math.sin(p) * math.cos(y) + math.sin(r) * math.cos(p) * math.sin(y),
            math.cos(r) * math.cos(p) * math.sin(y) - math.sin(r) * math.sin(p) * math.cos(y),
            math.cos(r) * math.cos(p) * math.cos(y) + math.sin(r) * math.sin(p) * math.sin(y))


def sim_time(offset_s):
    """T0 + offset as an exact rospy.Time (offset in whole nanoseconds)."""
    total_ns = T0_S * 1000000000 + int(round(offset_s * 1e9))
    return rospy.Time(total_ns // 1000000000, total_ns % 1000000000)


def read_rows(path):
    """Header and rows (lists of strings) of a CSV file; None if it does not exist or holds no header yet (the
    logger creates the file before its first flush: CI once read it empty in between)."""
    if not os.path.exists(path):
        return None
    with open(path, newline='') as f:
        lines = list(csv.reader(f))
    if not lines:
        return None
    return lines[0], lines[1:]


def wait_for(condition, timeout_s, what):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError('timed out after %.0f s waiting for %s' % (timeout_s, what))


class Logger(object):
    """A trajectory_logger child process with its own name, topics under /<name>/ and parameters."""

    def __init__(self, name, output_dir, server_params=None, **params):
        """`params` go on the command line (`_key:=value`); `server_params` on the parameter server first, for
        values a command line cannot carry (an empty string)."""
        self.name = name
        self.output_dir = output_dir
        self.topics = {
            'ground_truth': '/%s/ground_truth/odometry' % name,
            'navigation': '/%s/nav/odometry' % name,
            'usbl': '/%s/nav/usbl' % name,
            'datum': '/%s/nav/datum' % name,
        }
        executable = roslib.packages.find_node(PKG, 'trajectory_logger')
        if not executable:
            raise AssertionError('the trajectory_logger executable is not built (catkin_make)')
        args = [executable[0], '__name:=' + name]
        if output_dir is not None:
            args.append('_output_dir:=' + output_dir)
        server_params = server_params or {}
        for key, topic in self.topics.items():
            if key + '_topic' not in server_params:
                args.append('_%s_topic:=%s' % (key, topic))
        for key, value in params.items():
            args.append('_%s:=%s' % (key, value))
        for key, value in server_params.items():
            rospy.set_param('/%s/%s' % (name, key), value)
        fd, self.log_path = tempfile.mkstemp(prefix='trajectory_logger_%s_' % name, suffix='.log')
        self.log = os.fdopen(fd, 'w')
        self.process = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT)

    def output(self):
        self.log.flush()
        with open(self.log_path) as f:
            return f.read()

    def wait_exit(self, timeout_s=15.0):
        try:
            return self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            raise AssertionError('%s did not exit within %.0f s:\n%s' % (self.name, timeout_s, self.output()))

    def stop(self):
        """SIGINT, as roslaunch sends; returns the exit status."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        return self.wait_exit()

    def close(self):
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        self.log.close()
        if os.path.exists(self.log_path):
            os.remove(self.log_path)


class TrajectoryLoggerTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        rospy.init_node('trajectory_logger_check', anonymous=True)
        cls.clock_pub = rospy.Publisher('/clock', Clock, queue_size=10)
        cls.diagnostics = []
        rospy.Subscriber('/diagnostics', DiagnosticArray, cls.diagnostics.append, queue_size=100)

    def setUp(self):
        self.folder = tempfile.mkdtemp(prefix='trajectory_logger_test_')
        self.loggers = []

    def tearDown(self):
        for logger in self.loggers:
            logger.close()
        shutil.rmtree(self.folder, ignore_errors=True)

    # ---- helpers ----

    def start(self, name, output_dir='', server_params=None, **params):
        logger = Logger(name, self.folder if output_dir == '' else output_dir, server_params, **params)
        self.loggers.append(logger)
        return logger

    def connect(self, logger):
        """Publishers on the logger's topics, once it has subscribed to each."""
        pubs = {
            'ground_truth': rospy.Publisher(logger.topics['ground_truth'], Odometry, queue_size=100),
            'navigation': rospy.Publisher(logger.topics['navigation'], Odometry, queue_size=100),
            'usbl': rospy.Publisher(logger.topics['usbl'], NavSatFix, queue_size=100),
            'datum': rospy.Publisher(logger.topics['datum'], GeoDatum, queue_size=1, latch=True),
        }
        wait_for(lambda: all(p.get_num_connections() > 0 for p in pubs.values()) or logger.process.poll() is not None,
                 30.0, '%s to subscribe' % logger.name)
        self.assertIsNone(logger.process.poll(), 'the logger died at start-up:\n' + logger.output())
        time.sleep(0.5)  # its /clock subscription was made first but connects on its own
        return pubs

    def set_clock(self, offset_s):
        """Sets the sim clock and leaves the logger time to take it before the next message."""
        for _ in range(3):
            self.clock_pub.publish(Clock(clock=sim_time(offset_s)))
            time.sleep(0.05)
        time.sleep(0.25)

    @staticmethod
    def odometry(offset_s, east_m, north_m, up_m, rpy_deg, frame='utm', covariance=None):
        m = Odometry()
        m.header.stamp = sim_time(offset_s)
        m.header.frame_id = frame
        m.child_frame_id = 'base_link'
        m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = east_m, north_m, up_m
        q = quaternion(*rpy_deg)
        m.pose.pose.orientation.x, m.pose.pose.orientation.y, m.pose.pose.orientation.z, m.pose.pose.orientation.w = q
        if covariance is not None:
            cov = [0.0] * 36
            cov[0], cov[7], cov[14] = covariance
            m.pose.covariance = cov
        return m

    @staticmethod
    def fix(offset_s, lat_deg, lon_deg, sigma_m, status=NavSatStatus.STATUS_FIX):
        m = NavSatFix()
        m.header.stamp = sim_time(offset_s)
        m.header.frame_id = 'usbl_transponder'
        m.status.status = status
        m.latitude, m.longitude, m.altitude = lat_deg, lon_deg, -40.0
        m.position_covariance = [sigma_m ** 2, 0, 0, 0, sigma_m ** 2, 0, 0, 0, 1.0]
        m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        return m

    @staticmethod
    def datum(lat_deg, lon_deg, zone, northern):
        m = GeoDatum()
        m.header.stamp = sim_time(0.0)
        m.header.frame_id = 'utm'
        m.frame_id = 'utm'
        m.utm_zone = zone
        m.northern_hemisphere = northern
        m.epsg = (32600 if northern else 32700) + zone
        m.origin_latitude_deg, m.origin_longitude_deg = lat_deg, lon_deg
        m.origin_easting_m, m.origin_northing_m = lat_lon_to_utm(lat_deg, lon_deg, zone, northern)
        return m

    def wait_rows(self, path, count, timeout_s=10.0):
        def enough():
            table = read_rows(path)
            return table if table is not None and len(table[1]) >= count else None
        try:
            header, rows = wait_for(enough, timeout_s, '%d rows in %s' % (count, path))
        except AssertionError:
            table = read_rows(path)
            self.fail('%s: expected %d rows, found %s' % (path, count, None if table is None else len(table[1])))
        return header, rows

    def check_odometry_rows(self, path, sent, with_sigma):
        header, rows = self.wait_rows(path, len(sent))
        time.sleep(0.5)  # a row too many would come with the same flush
        header, rows = read_rows(path)
        self.assertEqual(header, NAV_COLUMNS if with_sigma else GT_COLUMNS)
        self.assertEqual(len(rows), len(sent), '%s: rows %s' % (path, [r[0] for r in rows]))
        for row, (msg, rpy_deg) in zip(rows, sent):
            self.assertEqual(row[0], stamp_text(msg.header.stamp))
            p = msg.pose.pose.position
            # Shortest round-trip printing: the doubles come back bit for bit.
            self.assertEqual([float(v) for v in row[1:4]], [p.x, p.y, p.z])
            for got, want in zip(row[4:7], rpy_deg):
                self.assertAlmostEqual(float(got), want, delta=1e-9)
            if with_sigma:
                cov = msg.pose.covariance
                self.assertAlmostEqual(float(row[7]), math.sqrt((cov[0] + cov[7]) / 2.0), delta=1e-12)
                self.assertAlmostEqual(float(row[8]), math.sqrt(cov[14]), delta=1e-12)

    def check_usbl_rows(self, path, sent, zone, northern):
        header, rows = self.wait_rows(path, len(sent))
        time.sleep(0.5)
        header, rows = read_rows(path)
        self.assertEqual(header, USBL_COLUMNS)
        self.assertEqual(len(rows), len(sent))
        for row, (msg, arrival_offset_s) in zip(rows, sent):
            self.assertEqual(row[0], stamp_text(msg.header.stamp))
            self.assertEqual(row[1], stamp_text(sim_time(arrival_offset_s)), 'arrival_s is the clock at reception')
            self.assertEqual(float(row[2]), msg.latitude)
            self.assertEqual(float(row[3]), msg.longitude)
            east_m, north_m = lat_lon_to_utm(msg.latitude, msg.longitude, zone, northern)
            self.assertAlmostEqual(float(row[4]), east_m, delta=1e-3)
            self.assertAlmostEqual(float(row[5]), north_m, delta=1e-3)
            self.assertAlmostEqual(float(row[6]), math.sqrt(msg.position_covariance[0]), delta=1e-12)

    def diagnostic_value(self, node, task, key):
        """Latest value of `key` in the /diagnostics status "<node>: <task>", or None."""
        for array in reversed(self.diagnostics):
            for status in array.status:
                if status.name == '%s: %s' % (node, task):
                    for kv in status.values:
                        if kv.key == key:
                            return kv.value
        return None

    # ---- cases ----

    def test_northern_dive(self):
        """Known values in UTM 31N: exact rows, a fix converted when the datum comes later, bad messages rejected
        without a crash and reported on /diagnostics, a new file set when the clock jumps back."""
        logger = self.start('logger_north', flush_period_s=0.2)
        pubs = self.connect(logger)
        lat0, lon0, zone = 43.0703, 5.8776, 31
        e0, n0 = lat_lon_to_utm(lat0, lon0, zone, True)

        # A fix before any datum: kept, converted once the datum arrives.
        usbl_sent = []
        self.set_clock(2.0)
        early = self.fix(0.5, 43.07031234567891, 5.877612345678912, 0.5)
        pubs['usbl'].publish(early)
        usbl_sent.append((early, 2.0))
        time.sleep(0.3)
        pubs['datum'].publish(self.datum(lat0, lon0, zone, True))
        time.sleep(0.3)

        gt_sent, nav_sent = [], []
        for k in range(20):
            rpy = (1.5 * math.sin(k), -2.0 + 0.1 * k, -170.0 + 17.5 * k)
            m = self.odometry(2.0 + 0.02 * k, e0 + 0.123456789 * k, n0 - 0.987654321 * k, -62.0 + 0.001 * k, rpy)
            pubs['ground_truth'].publish(m)
            gt_sent.append((m, rpy))
        for k in range(5):
            rpy = (0.5, 0.25, 30.0 + k)
            m = self.odometry(2.0 + 0.1 * k, e0 + 0.5 * k, n0 + 0.25 * k, -61.5, rpy, covariance=(4.0, 9.0, 0.04 + k))
            pubs['navigation'].publish(m)
            nav_sent.append((m, rpy))
        for k, arrival_s in enumerate([3.5, 4.5, 5.5]):
            self.set_clock(arrival_s)
            m = self.fix(arrival_s - 1.5, lat0 + 1e-5 * k, lon0 - 2e-5 * k, 0.5 + 0.1 * k)
            pubs['usbl'].publish(m)
            usbl_sent.append((m, arrival_s))
            time.sleep(0.3)  # the fix and the next /clock travel on two connections: let the fix arrive first

        # Bad input: each rejected, counted and survived.
        bad_gt = self.odometry(2.5, float('nan'), n0, -62.0, (0, 0, 0))
        pubs['ground_truth'].publish(bad_gt)
        # 0.18 s before the last one: out of order.
        pubs['ground_truth'].publish(self.odometry(2.2, e0, n0, -62.0, (0, 0, 0)))
        pubs['navigation'].publish(self.odometry(2.6, e0, n0, -61.5, (0, 0, 0), frame='map', covariance=(1, 1, 1)))
        pubs['navigation'].publish(self.odometry(2.7, e0, float('inf'), -61.5, (0, 0, 0), covariance=(1, 1, 1)))
        pubs['usbl'].publish(self.fix(4.8, lat0, lon0, 0.5, status=NavSatStatus.STATUS_NO_FIX))
        pubs['usbl'].publish(self.fix(4.9, float('nan'), lon0, 0.5))
        # ... and the node goes on logging good messages.
        for k in range(3):
            rpy = (0.0, 0.0, 90.0)
            m = self.odometry(3.0 + 0.02 * k, e0 - 1.0, n0 + 1.0, -62.5, rpy)
            pubs['ground_truth'].publish(m)
            gt_sent.append((m, rpy))

        self.check_odometry_rows(os.path.join(self.folder, 'ground_truth.csv'), gt_sent, with_sigma=False)
        self.check_odometry_rows(os.path.join(self.folder, 'navigation.csv'), nav_sent, with_sigma=True)
        self.check_usbl_rows(os.path.join(self.folder, 'usbl_fixes.csv'), usbl_sent, zone, True)
        self.assertIsNone(logger.process.poll(), 'the logger died:\n' + logger.output())
        output = logger.output()
        self.assertIn('/logger_north/ground_truth/odometry', output)
        self.assertIn('pose.pose.position.x is nan', output)
        self.assertIn("header.frame_id is 'map'", output)

        # /diagnostics: counts per topic, rejections, files.
        expected = {('ground truth', 'messages logged'): str(len(gt_sent)),
                    ('ground truth', 'messages rejected'): '2',
                    ('navigation', 'messages rejected'): '2',
                    ('USBL fixes', 'messages logged'): str(len(usbl_sent)),
                    ('USBL fixes', 'messages rejected'): '2',
                    ('datum', 'EPSG'): '32631'}
        wait_for(lambda: all(self.diagnostic_value('logger_north', task, key) == value
                             for (task, key), value in expected.items()),
                 10.0, '/diagnostics from logger_north with %s' % expected)
        self.assertIn('rows', self.diagnostic_value('logger_north', 'output files',
                                                    os.path.join(self.folder, 'ground_truth.csv')))

        # The clock jumps back (the bag replayed again): a new set of files, none of the old ones touched.
        before = read_rows(os.path.join(self.folder, 'ground_truth.csv'))
        self.set_clock(-100.0)
        replayed = [(self.odometry(-100.0 + 0.02 * k, e0, n0, -62.0, (0.0, 0.0, 45.0)), (0.0, 0.0, 45.0))
                    for k in range(4)]
        for m, _ in replayed:
            pubs['ground_truth'].publish(m)
        self.check_odometry_rows(os.path.join(self.folder, 'ground_truth_2.csv'), replayed, with_sigma=False)
        self.assertTrue(os.path.exists(os.path.join(self.folder, 'navigation_2.csv')))
        self.assertTrue(os.path.exists(os.path.join(self.folder, 'usbl_fixes_2.csv')))
        self.assertTrue(os.path.exists(os.path.join(self.folder, 'datum_2.json')))
        self.assertEqual(read_rows(os.path.join(self.folder, 'ground_truth.csv')), before)

        self.assertEqual(logger.stop(), 0, logger.output())

    def test_southern_dive(self):
        """UTM 23S (EPSG:32723), false northing 10 000 km; a fix beyond the zone's edge stays in the datum's zone."""
        logger = self.start('logger_south', flush_period_s=0.2)
        pubs = self.connect(logger)
        lat0, lon0, zone = -23.5, -45.1, 23
        self.set_clock(1.0)
        pubs['datum'].publish(self.datum(lat0, lon0, zone, False))
        time.sleep(0.3)
        sent = []
        points = [(-23.5, -45.1), (-23.51234567, -45.09876543), (-22.9, -47.95), (-24.2, -48.3), (-0.01, -45.0)]
        for k, (lat, lon) in enumerate(points):
            arrival_s = 2.0 + k
            self.set_clock(arrival_s)
            m = self.fix(arrival_s - 1.2, lat, lon, 2.0)
            pubs['usbl'].publish(m)
            sent.append((m, arrival_s))
            time.sleep(0.3)  # the fix and the next /clock travel on two connections: let the fix arrive first
        self.check_usbl_rows(os.path.join(self.folder, 'usbl_fixes.csv'), sent, zone, False)
        with open(os.path.join(self.folder, 'datum.json')) as f:
            text = f.read()
        self.assertIn('"epsg": 32723', text)
        self.assertIn('"northern_hemisphere": false', text)
        self.assertEqual(logger.stop(), 0, logger.output())

    def test_rows_survive_shutdown_and_crash(self):
        """Rows reach the disk at shutdown (long flush period) and, after a kill, every flushed row is whole; a
        second run in the same folder whose stamps go back (a bag played again) writes suffixed files instead of
        overwriting; a logger restarted after the kill, its stamps going on, appends to the files of the killed one
        (the partial row a crash can leave cut off)."""
        first = self.start('logger_shutdown', flush_period_s=60.0)
        pubs = self.connect(first)
        self.set_clock(1.0)
        sent = []
        for k in range(50):
            m = self.odometry(1.0 + 0.02 * k, 500000.0 + k, 4000000.0 - k, -10.0, (0.0, 0.0, 10.0))
            pubs['ground_truth'].publish(m)
            sent.append((m, (0.0, 0.0, 10.0)))
        time.sleep(1.0)
        self.assertEqual(read_rows(os.path.join(self.folder, 'ground_truth.csv'))[1], [],
                         'nothing flushed before the period or the shutdown')
        self.assertEqual(first.stop(), 0, first.output())
        self.check_odometry_rows(os.path.join(self.folder, 'ground_truth.csv'), sent, with_sigma=False)

        second = self.start('logger_crash', flush_period_s=0.2)
        pubs = self.connect(second)
        self.set_clock(2.0)
        for k in range(30):  # 1.5 s before the first run's last row: another timeline
            pubs['ground_truth'].publish(self.odometry(0.5 + 0.02 * k, 1.0 * k, 2.0, 3.0, (0.0, 0.0, 0.0)))
        self.wait_rows(os.path.join(self.folder, 'ground_truth_2.csv'), 30)
        second.process.send_signal(signal.SIGKILL)
        second.wait_exit()
        with open(os.path.join(self.folder, 'ground_truth_2.csv')) as f:
            text = f.read()
        self.assertTrue(text.endswith('\n'))
        lines = text.splitlines()
        self.assertEqual(len(lines), 31)
        self.assertTrue(all(len(line.split(',')) == len(GT_COLUMNS) for line in lines))
        self.assertEqual(len(read_rows(os.path.join(self.folder, 'ground_truth.csv'))[1]), 50, 'not overwritten')

        # The crash cut a row in the middle; the restarted logger goes on with the next stamps.
        with open(os.path.join(self.folder, 'ground_truth_2.csv'), 'a') as f:
            f.write('1.100000000,3.5,2')
        third = self.start('logger_restarted', flush_period_s=0.2)
        pubs = self.connect(third)
        self.set_clock(3.0)
        resumed = []
        for k in range(20):
            m = self.odometry(1.2 + 0.02 * k, 40.0 + k, 2.0, 3.0, (0.0, 0.0, 0.0))
            pubs['ground_truth'].publish(m)
            resumed.append(m)
        self.wait_rows(os.path.join(self.folder, 'ground_truth_2.csv'), 50)
        self.assertEqual(third.stop(), 0, third.output())
        self.assertIn('continuing the trajectory files', third.output())
        self.assertFalse(os.path.exists(os.path.join(self.folder, 'ground_truth_3.csv')), 'no new set after a restart')
        header, rows = read_rows(os.path.join(self.folder, 'ground_truth_2.csv'))
        self.assertEqual(header, GT_COLUMNS)
        self.assertEqual(len(rows), 50, 'the killed logger\'s 30 rows, then the restarted one\'s 20')
        self.assertTrue(all(len(r) == len(GT_COLUMNS) for r in rows), 'the partial row is cut off')
        self.assertEqual([r[0] for r in rows[30:]], [stamp_text(m.header.stamp) for m in resumed])

    def test_bad_parameters_fail_at_start_up(self):
        """Each bad parameter stops the node at once (exit 1) with a message naming it and its allowed range."""
        not_a_folder = os.path.join(self.folder, 'a_file')
        open(not_a_folder, 'w').close()
        cases = [
            ({'output_dir': None}, ['~output_dir', 'required']),
            ({'output_dir': os.path.join(not_a_folder, 'sub')}, ['~output_dir', 'cannot create']),
            ({'flush_period_s': 0}, ['~flush_period_s', '(0, 60]']),
            ({'flush_period_s': 61.5}, ['~flush_period_s', '(0, 60]']),
            ({'flush_period_s': 'often'}, ['~flush_period_s', 'must be a number']),
            ({'server': {'utm_frame': ''}}, ['~utm_frame', 'empty']),
            ({'server': {'usbl_topic': 'two words'}}, ['~usbl_topic', 'not a valid topic name']),
        ]
        for number, (params, words) in enumerate(cases):
            params = dict(params)
            output_dir = params.pop('output_dir', os.path.join(self.folder, 'run%d' % number))
            server_params = params.pop('server', None)
            logger = self.start('logger_bad_%d' % number, output_dir=output_dir, server_params=server_params,
                                **params)
            status = logger.wait_exit()
            self.assertEqual(status, 1, '%s: exit %s\n%s' % (params, status, logger.output()))
            for word in words:
                self.assertIn(word, logger.output(), params)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'trajectory_logger', TrajectoryLoggerTest)
