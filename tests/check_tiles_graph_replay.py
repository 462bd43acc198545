#!/usr/bin/env python3
"""Checks the tiles of a replay with the pose graph (run by tiles_graph_replay.test).

The sample out-and-back dive is replayed through the chain with the fusion's pose graph and live loop closure. The
checker plays the bag, flushes the tile writer, waits until no tile has been written or drawn again for a while
(bounded), then reads the newest version of every tile: some were drawn again (version >= 2, announced on
/mosaic/tile), every pair of overlapping tiles, consecutive or return pass, agrees within 2 px, and their mean
levels on their common pixels within 3 grey levels (the images' gains, solved over their overlaps). Then the dive is
drawn again after it (`recompose_tiles`, per image at the graph's final corrections): every overlapping pair of the
recomposed tiles agrees within 1.2 px, and in level within 3 grey levels.
"""
import atexit
import os
import signal
import subprocess
import time
import unittest

import rospy
import rostest
from exocet_msgs.msg import Tile as TileMsg
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from std_srvs.srv import Trigger

from exocet_mosaic import tile_analysis

MAX_PAIR_PX = 2.0  # issue 20: every pair of overlapping live tiles, return passes included
MAX_LEVEL_STEP_GREY = 3.0  # issue 20: mean-level difference between overlapping tiles
# Every overlapping pair after the dive, recomposed from the final graph with the images adjusted to one another.
# Issue 20's target is 1 px; bench_tiles reports it on the bench dives. On this dive the recomposed pairs measured
# 0.52 and 0.77 px in two runs of this test (the live run differs each time): the bound leaves that spread room.
MAX_RECOMPOSED_PAIR_PX = 1.2


class TilesGraphReplayTest(unittest.TestCase):

    def test_tiles_follow_the_graph(self):
        rospy.init_node('check_tiles_graph_replay')
        bag = rospy.get_param('~bag')
        output_dir = rospy.get_param('~output_dir')
        tiles_msgs, poses = [], []
        rospy.Subscriber('/mosaic/tile', TileMsg, tiles_msgs.append, queue_size=200)
        rospy.Subscriber('/mosaic/odometry', Odometry, poses.append, queue_size=1000)
        writer_diagnostics = {}

        def on_diagnostics(msg):
            for status in msg.status:
                if status.name.startswith('tile_writer'):
                    writer_diagnostics.update({kv.key: kv.value for kv in status.values})
        rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)
        time.sleep(1.0)
        topics = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
                  '/nav/altitude', '/nav/datum', '/tf_static']
        player = subprocess.Popen(['rosbag', 'play', '--clock', '-q', '-r', str(rospy.get_param('~rate')),
                                   '--queue=1000', '--wait-for-subscribers', bag, '--topics'] + topics,
                                  start_new_session=True)
        atexit.register(lambda: player.poll() is None and os.killpg(player.pid, signal.SIGKILL))
        last_count, last_change, start = -1, time.time(), time.time()
        while time.time() - last_change < 30.0 and time.time() - start < 300.0:
            if len(poses) != last_count:
                last_count, last_change = len(poses), time.time()
            if player.poll() is not None and time.time() - last_change > 4.0:
                break
            time.sleep(0.1)
        rospy.wait_for_service('/tile_writer/flush', timeout=10.0)
        reply = rospy.ServiceProxy('/tile_writer/flush', Trigger)()
        self.assertTrue(reply.success, reply.message)
        # Settled: no tile written or drawn again for 12 s (the registration of the tiles runs every 5 s), at most 120 s.
        last_count, last_change, start = len(tiles_msgs), time.time(), time.time()
        while time.time() - last_change < 12.0 and time.time() - start < 120.0:
            if len(tiles_msgs) != last_count:
                last_count, last_change = len(tiles_msgs), time.time()
            time.sleep(0.2)

        # The registrations of the tiles with each other measure only the pairs with a tile drawn since the last one.
        self.assertIn('tile pairs measured / reused by them', writer_diagnostics, writer_diagnostics)
        measured, reused = (int(v) for v in writer_diagnostics['tile pairs measured / reused by them'].split(' / '))
        rospy.loginfo('tiles_graph_replay: tile pairs measured %d, reused %d', measured, reused)
        self.assertGreater(measured, 0)
        self.assertGreater(reused, 0, 'a registration of unchanged tiles took their pairs from the cache')
        firsts = [m for m in tiles_msgs if m.version == 1]
        redrawn = [m for m in tiles_msgs if m.version >= 2]
        self.assertGreaterEqual(len(firsts), 3, 'several tiles written')
        self.assertTrue(redrawn, 'tiles drawn again as the graph moved their images')
        for m in redrawn:
            self.assertIn('_v%d.tif' % m.version, m.geotiff_path)
        tiles = tile_analysis.read_tiles(output_dir)
        self.assertEqual(len(tiles), len(firsts), 'one current version per tile on disk')
        pairs = tile_analysis.overlapping_pair_shifts(tiles)
        measured = [p for p in pairs if p.get('shift_px') is not None]
        returns = [p for p in measured if not p['consecutive']]
        self.assertTrue(returns, 'the return pass overlaps the outbound one')
        worst = max(measured, key=lambda p: p['shift_px'])
        rospy.loginfo('tiles_graph_replay: %d tiles, %d drawn again, %d pairs (%d return pass), worst %.2f px (%s, %s)',
                      len(tiles), len(redrawn), len(measured), len(returns), worst['shift_px'], worst['a'], worst['b'])
        self.assertLessEqual(worst['shift_px'], MAX_PAIR_PX,
                             '%s and %s disagree by %.2f px' % (worst['a'], worst['b'], worst['shift_px']))
        by_name = {t.name: t for t in tiles}
        steps = []
        for p in measured:
            colour = tile_analysis.pair_colour_difference(by_name[p['a']], by_name[p['b']], p['dx_px'], p['dy_px'])
            if colour is not None:
                steps.append((abs(colour['level_step_grey']), p['a'], p['b']))
        self.assertTrue(steps, 'the level of overlapping tiles measured')
        step = max(steps)
        rospy.loginfo('tiles_graph_replay: largest level step %.2f grey (%s, %s) over %d pairs', step[0], step[1],
                      step[2], len(steps))
        self.assertLessEqual(step[0], MAX_LEVEL_STEP_GREY,
                             '%s and %s differ in level by %.2f grey' % (step[1], step[2], step[0]))

        # After the dive: the whole dive drawn again from the final graph (the corrections the writer saved).
        recomposed_dir = output_dir.rstrip('/') + '_recomposed'
        os.makedirs(recomposed_dir, exist_ok=True)
        done = subprocess.run(['rosrun', 'exocet_mosaic', 'recompose_tiles', '--tiles', output_dir, '--output',
                               recomposed_dir], capture_output=True, text=True, timeout=300)
        self.assertEqual(done.returncode, 0, 'recompose_tiles failed: %s' % (done.stderr or done.stdout))
        recomposed = tile_analysis.read_tiles(recomposed_dir)
        self.assertEqual(len(recomposed), len(tiles), 'every tile recomposed')
        measured = [p for p in tile_analysis.overlapping_pair_shifts(recomposed) if p.get('shift_px') is not None]
        self.assertTrue([p for p in measured if not p['consecutive']], 'the recomposed return pass overlaps')
        worst = max(measured, key=lambda p: p['shift_px'])
        by_name = {t.name: t for t in recomposed}
        steps = [abs(c['level_step_grey']) for c in
                 (tile_analysis.pair_colour_difference(by_name[p['a']], by_name[p['b']], p['dx_px'], p['dy_px'])
                  for p in measured) if c is not None]
        rospy.loginfo('tiles_graph_replay: recomposed: %d pairs, worst %.2f px (%s, %s), largest level step %.2f grey',
                      len(measured), worst['shift_px'], worst['a'], worst['b'], max(steps))
        self.assertLessEqual(worst['shift_px'], MAX_RECOMPOSED_PAIR_PX,
                             'recomposed %s and %s disagree by %.2f px' % (worst['a'], worst['b'], worst['shift_px']))
        self.assertLessEqual(max(steps), MAX_LEVEL_STEP_GREY, 'recomposed level step %.2f grey' % max(steps))


if __name__ == '__main__':
    rostest.rosrun('exocet_system_tests', 'tiles_graph_replay', TilesGraphReplayTest)
