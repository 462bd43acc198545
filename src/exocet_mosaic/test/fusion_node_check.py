#!/usr/bin/env python3
"""Drives fusion_node with inputs made here (run by fusion_node.test).

A vehicle flies a straight line at a known speed and heading, level, at a known height. The checker publishes its
static mounts on tf, the IMU attitude, the altimeter, a drifting dead reckoning in UTM, late USBL fixes in WGS 84
(one of them an outlier), and the image motion the downward camera would see (translation model). Bad input is
slipped in on purpose: a NaN dead reckoning, a latitude out of range, a failed registration. Checks: the fused
camera position against the truth, the outlier gated, every bad input counted on /diagnostics and the node alive,
and a clock jump resetting the filter. A second node (namespace /nonav) has no navigation at all: the operator's
~set_initial_pose starts it and the images alone carry the track, its covariance growing.
"""
import math
import random
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from exocet_msgs.msg import ImageMotion
from exocet_msgs.srv import SetInitialPose
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from sensor_msgs.msg import CameraInfo, Imu, NavSatFix, NavSatStatus, Range
from tf2_msgs.msg import TFMessage

from exocet_mosaic.testing import lat_lon_to_utm, utm_to_lat_lon

PKG = 'exocet_mosaic'
ZONE, NORTHERN = 31, True
LAT0, LON0 = 43.0712, 5.8790
FX, CX, CY = 623.5, 359.5, 287.5
HEIGHT_M = 2.5          # camera above the seabed
SPEED_MPS = 0.5
HEADING_DEG = 60.0      # clockwise from grid north
LEVER_ARM = (0.4, 0.0, -0.3)   # camera in base_link
T0 = 1000.0


def yaw_quaternion(enu_yaw):
    return (0.0, 0.0, math.sin(enu_yaw / 2.0), math.cos(enu_yaw / 2.0))


class Truth:
    """The vehicle's true state at dive time t (s)."""

    def __init__(self):
        self.e0, self.n0 = lat_lon_to_utm(LAT0, LON0, ZONE, NORTHERN)
        self.heading = math.radians(HEADING_DEG)
        self.enu_yaw = math.pi / 2.0 - self.heading

    def base(self, t):
        d = SPEED_MPS * t
        return self.e0 + d * math.sin(self.heading), self.n0 + d * math.cos(self.heading)

    def camera(self, t):
        e, n = self.base(t)
        # Lever arm turned by the heading (level vehicle): forward component along the heading.
        fwd, left = LEVER_ARM[0], LEVER_ARM[1]
        return (e + fwd * math.cos(self.enu_yaw) - left * math.sin(self.enu_yaw),
                n + fwd * math.sin(self.enu_yaw) + left * math.cos(self.enu_yaw))


class Diagnostics:
    def __init__(self, name_part):
        self.lock = threading.Lock()
        self.values = {}
        self.name_part = name_part
        rospy.Subscriber('/diagnostics', DiagnosticArray, self.on_diagnostics)

    def on_diagnostics(self, msg):
        for status in msg.status:
            if self.name_part in status.name:
                with self.lock:
                    self.values = {kv.key: kv.value for kv in status.values}
                    self.values['__level'] = status.level
                    self.values['__message'] = status.message

    def count(self, key):
        with self.lock:
            return int(self.values.get(key, '0'))

    def get(self, key):
        with self.lock:
            return self.values.get(key)


def static_tf():
    msg = TFMessage()
    # base_link -> camera_optical: x starboard, y aft, z down (as the simulator's rig).
    cam = TransformStamped()
    cam.header.frame_id = 'base_link'
    cam.child_frame_id = 'camera_optical'
    cam.transform.translation.x, cam.transform.translation.y, cam.transform.translation.z = LEVER_ARM
    # Rotation matrix columns (0,-1,0), (-1,0,0), (0,0,-1): a 180 degree turn about (1,-1,0)/sqrt(2).
    s = math.sqrt(0.5)
    cam.transform.rotation.x, cam.transform.rotation.y, cam.transform.rotation.z, cam.transform.rotation.w = s, -s, 0, 0
    alt = TransformStamped()
    alt.header.frame_id = 'base_link'
    alt.child_frame_id = 'altimeter'
    alt.transform.rotation.w = 1.0
    usbl = TransformStamped()
    usbl.header.frame_id = 'base_link'
    usbl.child_frame_id = 'usbl_transponder'
    usbl.transform.translation.z = 0.5
    usbl.transform.rotation.w = 1.0
    msg.transforms = [cam, alt, usbl]
    return msg


def motion_message(t_prev, t, displacement_m, failed=False, ns=''):
    """The translation a downward camera sees when the vehicle moves forward by displacement_m: the seabed slides
    towards the image bottom (image y is aft)."""
    msg = ImageMotion()
    # Rounded so that a pair's previous stamp is exactly the previous pair's stamp, as the registration gives them.
    msg.header.stamp = rospy.Time.from_sec(round(t, 6))
    msg.header.frame_id = 'camera_optical'
    msg.previous_stamp = rospy.Time.from_sec(round(t_prev, 6))
    msg.method = 'klt'
    msg.model = 'translation'
    ty = FX * displacement_m / HEIGHT_M
    msg.matrix = [1, 0, 0, 0, 1, ty, 0, 0, 1] if not failed else [1, 0, 0, 0, 1, 0, 0, 0, 1]
    msg.centre_px = [CX, CY]
    msg.parameters = [0.0, ty] if not failed else []
    msg.covariance = [0.01, 0.0, 0.0, 0.01] if not failed else []
    msg.failed = failed
    msg.failure = 'too_few_tracks' if failed else 'none'
    msg.image_width, msg.image_height = 720, 576
    msg.camera_matrix = [FX, 0, CX, 0, FX, CY, 0, 0, 1]
    return msg


class FusionNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node('fusion_node_check')
        cls.truth = Truth()
        cls.odometry = {}
        cls.nonav_odometry = []
        rospy.Subscriber('/mosaic/odometry', Odometry, lambda m: cls.odometry.__setitem__(m.header.stamp.to_sec(), m))
        rospy.Subscriber('/nonav/odometry', Odometry, lambda m: cls.nonav_odometry.append(m))
        cls.diag = Diagnostics('fusion_node_under_test')
        cls.diag_nonav = Diagnostics('nonav_fusion')
        cls.pub_tf = rospy.Publisher('/tf_static', TFMessage, queue_size=1, latch=True)
        cls.pub_imu = rospy.Publisher('/nav/imu', Imu, queue_size=1000)
        cls.pub_alt = rospy.Publisher('/nav/altitude', Range, queue_size=1000)
        cls.pub_odom = rospy.Publisher('/nav/odometry', Odometry, queue_size=1000)
        cls.pub_usbl = rospy.Publisher('/nav/usbl', NavSatFix, queue_size=100)
        cls.pub_motion = rospy.Publisher('/mosaic/motion', ImageMotion, queue_size=1000)
        cls.pub_nonav_motion = rospy.Publisher('/nonav/motion', ImageMotion, queue_size=1000)
        cls.pub_tf.publish(static_tf())
        deadline = time.time() + 20.0
        while time.time() < deadline and (cls.pub_motion.get_num_connections() == 0 or
                                          cls.pub_odom.get_num_connections() == 0 or
                                          cls.pub_nonav_motion.get_num_connections() == 0):
            time.sleep(0.1)
        time.sleep(1.0)

    # -----------------------------------------------------------------------------------------------------------
    def publish_dive(self, duration_s, outlier_at_s, rng):
        truth = self.truth
        dt = 0.02  # IMU at 50 Hz drives the loop
        pending_fixes = []
        steps = int(duration_s / dt)
        for k in range(steps + 1):
            t = k * dt
            stamp = rospy.Time.from_sec(T0 + t)
            imu = Imu()
            imu.header.stamp = stamp
            imu.header.frame_id = 'base_link'
            (imu.orientation.x, imu.orientation.y, imu.orientation.z,
             imu.orientation.w) = yaw_quaternion(truth.enu_yaw)
            imu.orientation_covariance[0] = 1e-6
            self.pub_imu.publish(imu)
            if k % 5 == 0:  # 10 Hz: altimeter and dead reckoning
                rng_msg = Range()
                rng_msg.header.stamp = stamp
                rng_msg.header.frame_id = 'altimeter'
                rng_msg.min_range, rng_msg.max_range = 0.1, 50.0
                rng_msg.range = HEIGHT_M - LEVER_ARM[2]  # the camera hangs 0.3 m below the altimeter
                self.pub_alt.publish(rng_msg)
                e, n = truth.base(t)
                drift = 0.02 * SPEED_MPS * t  # 2% of the distance, sideways
                odom = Odometry()
                odom.header.stamp = stamp
                odom.header.frame_id = 'utm'
                odom.child_frame_id = 'base_link'
                odom.pose.pose.position.x = e + drift * math.cos(truth.heading)
                odom.pose.pose.position.y = n - drift * math.sin(truth.heading)
                odom.pose.pose.position.z = -45.0
                (odom.pose.pose.orientation.x, odom.pose.pose.orientation.y, odom.pose.pose.orientation.z,
                 odom.pose.pose.orientation.w) = yaw_quaternion(truth.enu_yaw)
                sigma = 0.05 + 0.02 * SPEED_MPS * t
                odom.pose.covariance[0] = odom.pose.covariance[7] = sigma * sigma
                self.pub_odom.publish(odom)
            if k % 10 == 0 and k > 0:  # 5 Hz: image motion
                self.pub_motion.publish(motion_message(T0 + t - 0.2, T0 + t, SPEED_MPS * 0.2))
            if k % 50 == 0:  # 1 Hz USBL, arriving 1.5 s after the measurement
                e, n = truth.base(t)
                e += rng.gauss(0.0, 0.5)
                n += rng.gauss(0.0, 0.5)
                if abs(t - outlier_at_s) < 1e-6:
                    e += 25.0
                lat, lon = utm_to_lat_lon(e, n, ZONE, NORTHERN)
                fix = NavSatFix()
                fix.header.stamp = stamp
                fix.header.frame_id = 'base_link'
                fix.status.status = NavSatStatus.STATUS_FIX
                fix.latitude, fix.longitude, fix.altitude = lat, lon, -45.0
                fix.position_covariance = [0.25, 0, 0, 0, 0.25, 0, 0, 0, 0.09]
                fix.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
                pending_fixes.append((t + 1.5, fix))
            while pending_fixes and pending_fixes[0][0] <= t:
                self.pub_usbl.publish(pending_fixes.pop(0)[1])
            time.sleep(dt / 10.0)  # 10x real time

    def test_1_fuses_rejects_bad_input_and_gates_outliers(self):
        rng = random.Random(7)
        # Bad input first: it must be rejected without stopping the node.
        bad = Odometry()
        bad.header.stamp = rospy.Time.from_sec(T0 - 0.5)
        bad.header.frame_id = 'utm'
        bad.pose.pose.position.x = float('nan')
        self.pub_odom.publish(bad)
        bad_fix = NavSatFix()
        bad_fix.header.stamp = rospy.Time.from_sec(T0 - 0.5)
        bad_fix.status.status = NavSatStatus.STATUS_FIX
        bad_fix.latitude, bad_fix.longitude = 95.0, 5.0
        self.pub_usbl.publish(bad_fix)
        self.publish_dive(40.0, outlier_at_s=20.0, rng=rng)
        # A registration failure in the middle of nowhere (after the dive): carried by the navigation.
        self.pub_motion.publish(motion_message(T0 + 40.0, T0 + 40.2, 0.0, failed=True))
        time.sleep(3.0)
        self.assertGreater(len(self.odometry), 150, 'one odometry per image motion')
        # The fused position near the end of the line against the truth.
        errors = []
        for stamp, odom in self.odometry.items():
            t = stamp - T0
            if not 5.0 <= t <= 39.0:
                continue
            e, n = self.truth.camera(t)
            errors.append(math.hypot(odom.pose.pose.position.x - e, odom.pose.pose.position.y - n))
            sigma = math.sqrt(max(odom.pose.covariance[0], odom.pose.covariance[7]))
            self.assertGreater(sigma, 0.0)
        rms = math.sqrt(sum(x * x for x in errors) / len(errors))
        dr_error_end = 0.02 * SPEED_MPS * 39.0
        self.assertLess(rms, 0.35, 'fused RMS error %.3f m (dead reckoning drifts to %.2f m)' % (rms, dr_error_end))
        deadline = time.time() + 5.0
        while time.time() < deadline and self.diag.count('gated: fix') < 1:
            time.sleep(0.2)
        self.assertGreaterEqual(self.diag.count('gated: fix'), 1, 'the 25 m outlier is gated')
        self.assertGreaterEqual(self.diag.count('rejected inputs: dead reckoning'), 1, 'NaN dead reckoning')
        self.assertGreaterEqual(self.diag.count('rejected inputs: fix'), 1, 'latitude 95')
        self.assertGreaterEqual(self.diag.count('image motion failures'), 1)
        self.assertGreaterEqual(self.diag.count('applied: fix'), 30)
        self.assertEqual(self.diag.get('initialised'), 'True')
        # What the heap holds (make soak fits its slope): a node with a filter and its tracks holds MBs, not GBs.
        self.assertTrue(1.0 < float(self.diag.get('heap in use (MB)')) < 4096.0, self.diag.get('heap in use (MB)'))
        self.assertGreaterEqual(float(self.diag.get('heap freed, kept by malloc (MB)')), 0.0)
        # The node runs on jemalloc (exocet_long_running_allocator), found at run time.
        self.assertEqual(self.diag.get('heap allocator'), 'jemalloc')

    def test_2_clock_jump_resets(self):
        # One input from 500 s before the newest is late (a starved node upstream): dropped, no reset. A stream of
        # them, none in order, is the dive replayed again without its clock: a reset once it lasts 3 s.
        resets_before = self.diag.count('resets')
        late_before = self.diag.count('late inputs dropped')
        odom = Odometry()
        odom.header.frame_id = 'utm'
        odom.pose.pose.position.x, odom.pose.pose.position.y = self.truth.base(0.0)
        odom.pose.pose.orientation.w = 1.0
        odom.pose.covariance[0] = odom.pose.covariance[7] = 0.01
        odom.header.stamp = rospy.Time.from_sec(T0 - 500.0)
        self.pub_odom.publish(odom)
        deadline = time.time() + 5.0
        while time.time() < deadline and self.diag.count('late inputs dropped') <= late_before:
            time.sleep(0.2)
        self.assertGreater(self.diag.count('late inputs dropped'), late_before, 'one late input is dropped')
        self.assertEqual(self.diag.count('resets'), resets_before, 'one late input does not reset the filter')
        start = time.time()
        k = 0
        while time.time() - start < 6.0 and self.diag.count('resets') <= resets_before:
            k += 1
            odom.header.stamp = rospy.Time.from_sec(T0 - 500.0 + 0.1 * k)  # a bag replayed again, no clock
            self.pub_odom.publish(odom)
            time.sleep(0.1)
        deadline = time.time() + 5.0
        while time.time() < deadline and self.diag.count('resets') <= resets_before:
            time.sleep(0.2)
        self.assertGreater(self.diag.count('resets'), resets_before)

    def test_3_no_navigation_images_alone(self):
        rospy.wait_for_service('/nonav_fusion/set_initial_pose', timeout=20.0)
        set_pose = rospy.ServiceProxy('/nonav_fusion/set_initial_pose', SetInitialPose)
        refused = set_pose(latitude_deg=95.0, longitude_deg=5.0, easting_m=float('nan'), northing_m=float('nan'),
                           heading_deg=HEADING_DEG, altitude_m=HEIGHT_M, position_sigma_m=1.0)
        self.assertFalse(refused.success)
        self.assertIn('latitude', refused.message)
        e0, n0 = self.truth.camera(0.0)
        lat, lon = utm_to_lat_lon(e0, n0, ZONE, NORTHERN)
        reply = set_pose(latitude_deg=lat, longitude_deg=lon, easting_m=float('nan'), northing_m=float('nan'),
                         heading_deg=HEADING_DEG, altitude_m=HEIGHT_M, position_sigma_m=0.5)
        self.assertTrue(reply.success, reply.message)
        for k in range(1, 101):  # 20 s at 5 Hz
            t = 0.2 * k
            self.pub_nonav_motion.publish(motion_message(T0 + t - 0.2, T0 + t, SPEED_MPS * 0.2))
            time.sleep(0.01)
        deadline = time.time() + 5.0
        while time.time() < deadline and len(self.nonav_odometry) < 100:
            time.sleep(0.1)
        self.assertGreaterEqual(len(self.nonav_odometry), 99)
        last = self.nonav_odometry[-1]
        e, n = self.truth.camera(last.header.stamp.to_sec() - T0)
        error = math.hypot(last.pose.pose.position.x - e, last.pose.pose.position.y - n)
        self.assertLess(error, 0.05, 'images alone along a straight line: %.3f m off after 10 m' % error)
        sigmas = [math.sqrt(o.pose.covariance[0] + o.pose.covariance[7]) for o in self.nonav_odometry]
        self.assertGreater(sigmas[-1], sigmas[0], 'the uncertainty grows with image motion alone')
        self.assertTrue(all(b >= a - 1e-9 for a, b in zip(sigmas, sigmas[1:])), 'and never shrinks')

    def test_4_late_image_motion_is_waited_for(self):
        """A replay faster than real time delays the registration's motions: each image's motion arrives 1 s (sim)
        after navigation stamped later. The node waits for it (the image was announced on camera_info), so the
        odometry published at an image is the state at that image, not 1 s (0.5 m) later."""
        truth = self.truth
        published = {}
        rospy.Subscriber('/wait/odometry', Odometry, lambda m: published.__setitem__(m.header.stamp.to_sec(), m))
        diag = Diagnostics('waiting_fusion')
        pub_imu = rospy.Publisher('/wait/nav/imu', Imu, queue_size=1000)
        pub_alt = rospy.Publisher('/wait/nav/altitude', Range, queue_size=1000)
        pub_odom = rospy.Publisher('/wait/nav/odometry', Odometry, queue_size=1000)
        pub_info = rospy.Publisher('/wait/camera_info', CameraInfo, queue_size=1000)
        pub_motion = rospy.Publisher('/wait/motion', ImageMotion, queue_size=1000)
        deadline = time.time() + 20.0
        while time.time() < deadline and any(p.get_num_connections() == 0
                                             for p in (pub_imu, pub_alt, pub_odom, pub_info, pub_motion)):
            time.sleep(0.1)
        time.sleep(0.5)
        dt, delay_s, duration_s = 0.02, 1.0, 12.0
        late_motions = []
        for k in range(int(duration_s / dt) + 1):
            t = k * dt
            stamp = rospy.Time.from_sec(T0 + t)
            imu = Imu()
            imu.header.stamp = stamp
            imu.header.frame_id = 'base_link'
            (imu.orientation.x, imu.orientation.y, imu.orientation.z,
             imu.orientation.w) = yaw_quaternion(truth.enu_yaw)
            imu.orientation_covariance[0] = 1e-6
            pub_imu.publish(imu)
            if k % 5 == 0:
                alt = Range()
                alt.header.stamp = stamp
                alt.header.frame_id = 'altimeter'
                alt.min_range, alt.max_range = 0.1, 50.0
                alt.range = HEIGHT_M - LEVER_ARM[2]
                pub_alt.publish(alt)
                e, n = truth.base(t)
                odom = Odometry()
                odom.header.stamp = stamp
                odom.header.frame_id = 'utm'
                odom.child_frame_id = 'base_link'
                odom.pose.pose.position.x, odom.pose.pose.position.y, odom.pose.pose.position.z = e, n, -45.0
                (odom.pose.pose.orientation.x, odom.pose.pose.orientation.y, odom.pose.pose.orientation.z,
                 odom.pose.pose.orientation.w) = yaw_quaternion(truth.enu_yaw)
                odom.pose.covariance[0] = odom.pose.covariance[7] = 0.05 ** 2
                pub_odom.publish(odom)
            if k % 10 == 0:  # an image at 5 Hz: its camera_info now, its motion 1 s later
                info = CameraInfo()
                info.header.stamp = stamp
                info.header.frame_id = 'camera_optical'
                info.width, info.height = 720, 576
                info.K = [FX, 0, CX, 0, FX, CY, 0, 0, 1]
                pub_info.publish(info)
                if k > 0:
                    late_motions.append((t + delay_s, motion_message(T0 + t - 0.2, T0 + t, SPEED_MPS * 0.2)))
            while late_motions and late_motions[0][0] <= t + 1e-9:
                pub_motion.publish(late_motions.pop(0)[1])
            time.sleep(dt / 10.0)
        for _, msg in late_motions:
            pub_motion.publish(msg)
        deadline = time.time() + 10.0
        while time.time() < deadline and len(published) < 55:
            time.sleep(0.1)
        image_stamps = sorted(s for s in published if abs(round((s - T0) / 0.2) * 0.2 - (s - T0)) < 1e-4)
        self.assertGreaterEqual(len(image_stamps), 50, 'an odometry at each image')
        errors = []
        for s in image_stamps:
            if s - T0 < 2.0:
                continue
            e, n = truth.camera(s - T0)
            p = published[s].pose.pose.position
            errors.append(math.hypot(p.x - e, p.y - n))
        print('late motions: %d image odometries, error max %.3f m (a state 1 s late would be %.2f m off)'
              % (len(image_stamps), max(errors), SPEED_MPS * delay_s))
        self.assertLess(max(errors), 0.15, 'the odometry at an image is the state at that image')
        deadline = time.time() + 5.0
        while time.time() < deadline and diag.get('images awaiting their motion') != '0':
            time.sleep(0.2)
        self.assertEqual(diag.get('images awaiting their motion'), '0')
        self.assertEqual(diag.count('motion waits timed out'), 0)


if __name__ == '__main__':
    rostest.rosrun(PKG, 'fusion_node_check', FusionNodeTest)
