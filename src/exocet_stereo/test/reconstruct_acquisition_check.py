#!/usr/bin/env python3
"""End-to-end check of the reconstruction (run by reconstruct_acquisition.test): waits for the acquisition
sequencer's bag, runs reconstruct_acquisition on it, and measures the fused cloud and the surface against the true
vent of the simulator (exocet_servo's ArmRigConfig default scene: base centre (1.3, 0, -0.2) m, 0.3 m high, radius
0.1 m at the base and 0.05 m at the top, on the seabed plane z = -0.2 m)."""
import os
import subprocess
import time
import unittest

import numpy as np
import rospy
import rostest
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from std_srvs.srv import Trigger

PKG = 'exocet_stereo'
BASE = np.array([1.3, 0.0, -0.2])
HEIGHT, R_BASE, R_TOP = 0.3, 0.1, 0.05


def read_ply_vertices(path):
    with open(path, 'rb') as f:
        count = 0
        while True:
            line = f.readline().decode().strip()
            if line.startswith('element vertex'):
                count = int(line.split()[2])
            if line == 'end_header':
                break
        return np.array([[float(v) for v in f.readline().split()[:3]] for _ in range(count)])


def distance_to_vent(points):
    """Distance to the nearest true surface (chimney side, top, seabed), and each point's radius and height."""
    q = points - BASE
    r, h = np.hypot(q[:, 0], q[:, 1]), q[:, 2]
    a, b = np.array([R_BASE, 0.0]), np.array([R_TOP, HEIGHT])
    rh = np.stack([r, h], 1)
    t = np.clip(((rh - a) @ (b - a)) / ((b - a) @ (b - a)), 0.0, 1.0)
    side = np.linalg.norm(rh - (a + t[:, None] * (b - a)), axis=1)
    top = np.where(r <= R_TOP, np.abs(h - HEIGHT), np.hypot(r - R_TOP, h - HEIGHT))
    return np.minimum(np.minimum(side, top), np.abs(h)), r, h


class ReconstructAcquisition(unittest.TestCase):
    def test_reconstruction_of_the_servoed_acquisition_is_metric(self):
        status = {'text': None}
        rospy.Subscriber('/acquisition_sequencer/status', String, lambda m: status.update(text=m.data))
        deadline = time.time() + 400.0
        while time.time() < deadline and not rospy.is_shutdown():
            if status['text'] and (status['text'].startswith('done') or status['text'].startswith('failed')):
                break
            time.sleep(0.2)
        self.assertIsNotNone(status['text'])
        self.assertTrue(status['text'].startswith('done'), status['text'])
        out = rospy.get_param('~output_dir')
        tool = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', '..', 'devel', 'lib', PKG,
                            'reconstruct_acquisition')
        if not os.path.exists(tool):
            tool = subprocess.check_output(['catkin_find', '--first-only', PKG, 'reconstruct_acquisition'],
                                           text=True).strip()
        run = subprocess.run([tool, '--bag', rospy.get_param('~bag'), '--output-dir', out], capture_output=True,
                             text=True, timeout=300)
        rospy.loginfo('reconstruct_acquisition:\n%s%s', run.stdout, run.stderr)
        self.assertEqual(run.returncode, 0, run.stderr)
        for name in ('fused_cloud.ply', 'surface.ply', 'surface.obj', 'surface.wrl'):
            self.assertTrue(os.path.getsize(os.path.join(out, name)) > 0, name)
        for name, bound_pct in (('fused_cloud.ply', 0.5), ('surface.ply', 0.5)):
            d, r, h = distance_to_vent(read_ply_vertices(os.path.join(out, name)))
            chimney = (r < 1.5 * R_BASE) & (h > 0.005) & (h < HEIGHT + 0.01)
            self.assertGreater(chimney.sum(), 1000, name)
            rms_pct = 100.0 * np.sqrt(np.mean(d[chimney] ** 2)) / HEIGHT
            rospy.loginfo('%s: %d points on the chimney, RMS %.3f mm = %.3f %% of the height', name,
                          chimney.sum(), 1000.0 * HEIGHT * rms_pct / 100.0, rms_pct)
            self.assertLess(rms_pct, bound_pct, name)
        cli_points = len(read_ply_vertices(os.path.join(out, 'fused_cloud.ply')))

        # The node: the same reconstruction on ~reconstruct, the cloud and the surface published for rviz.
        received = {}
        progress = {'text': None}
        rospy.Subscriber('/reconstruction/cloud', PointCloud2, lambda m: received.update(cloud=m))
        # The marker's Python message package is not installed here: its serialised size says it holds the triangles.
        rospy.Subscriber('/reconstruction/surface', rospy.AnyMsg, lambda m: received.update(surface=m))
        rospy.Subscriber('/reconstruction/progress', String, lambda m: progress.update(text=m.data))
        rospy.wait_for_service('/reconstruction/reconstruct', 30.0)
        answer = rospy.ServiceProxy('/reconstruction/reconstruct', Trigger)()
        self.assertTrue(answer.success, answer.message)
        deadline = time.time() + 300.0
        while time.time() < deadline and not rospy.is_shutdown():
            text = progress['text'] or ''
            if (text.startswith('done') or text.startswith('failed')) and 'cloud' in received and 'surface' in received:
                break
            if text.startswith('failed'):
                break
            time.sleep(0.2)
        self.assertTrue((progress['text'] or '').startswith('done'), progress['text'])
        cloud = received['cloud']
        rospy.loginfo('reconstruction_node: %s; cloud %d points, surface about %d triangles', progress['text'],
                      cloud.width * cloud.height, len(received['surface']._buff) // 24 // 3)
        self.assertEqual(cloud.header.frame_id, 'arm_base')
        self.assertEqual(cloud.width * cloud.height, cli_points)
        self.assertGreater(len(received['surface']._buff), 24 * 3000)  # 3000 vertices of 3 doubles
        self.assertTrue(os.path.exists('/tmp/exocet_reconstruction_node_test/surface.wrl'))


if __name__ == '__main__':
    rospy.init_node('reconstruct_acquisition_check')
    rostest.rosrun(PKG, 'reconstruct_acquisition', ReconstructAcquisition)
