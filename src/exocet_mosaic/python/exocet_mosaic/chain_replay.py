"""What the chain's benchmarks share (bench_tiles, soak_dive): the simulated dives rendered once into out/bench/cache/,
a private ROS master, the chain's processes found and sampled in /proc, and a listener to the chain's outputs."""
import math
import os
import re
import shutil
import signal
import socket
import subprocess
import threading
import time

import numpy as np
import yaml

from exocet_mosaic import tile_analysis

IMAGE_TOPICS = ('/camera/image_raw/compressed', '/camera/image_raw')
NODES = ('registration', 'fusion', 'tile_writer')  # the chain's nodes sampled by default


def rnd(x, digits=4):
    return None if x is None else round(float(x), digits)


def log(message):
    print(message, flush=True)


# ---------------------------------------------------------------------------------------------------------------
# Dives.

def ensure_bag(root, name):
    """Renders config/dives/<name>.yaml into out/bench/cache/<name>.bag unless the cached bag is newer than both
    the description and the simulator. Returns the bag path, or None when it cannot be made."""
    config = os.path.join(root, 'src', 'exocet_mosaic', 'config', 'dives', name + '.yaml')
    synth = os.path.join(root, 'devel', 'lib', 'exocet_mosaic', 'dive_synth')
    cache = os.path.join(root, 'out', 'bench', 'cache')
    bag = os.path.join(cache, name + '.bag')
    if not os.path.exists(config) or not os.access(synth, os.X_OK):
        log('%s or %s missing' % (config, synth))
        return None
    # The simulator's library and the bag writer's sources, not dive_synth itself: the executable is relinked
    # whenever any node's code changes, which does not change the bag.
    inputs = [config, os.path.join(root, 'devel', 'lib', 'libexocet_mosaic_sim.so')] + [
        os.path.join(root, 'src', 'exocet_mosaic', f) for f in (
            'src/tools/dive_synth.cpp', 'src/ros/dive_bag_writer.cpp', 'include/exocet_mosaic/ros/dive_bag_writer.h')]
    inputs += description_files(config)
    newest_input = max(os.path.getmtime(f) if os.path.exists(f) else os.path.getmtime(synth) for f in inputs)
    if os.path.exists(bag) and os.path.getmtime(bag) > newest_input:
        return bag
    os.makedirs(cache, exist_ok=True)
    log('rendering %s (cached for the next runs)' % bag)
    start = time.time()
    subprocess.check_call([synth, '--config', config, '--output', bag, '--threads', str(os.cpu_count() or 2)])
    log('rendered in %.0f s' % (time.time() - start))
    return bag


def description_files(config):
    """Files a dive description reads (a waypoints CSV, a seabed image, intrinsics), resolved as dive_synth resolves
    them (relative to the description's folder): the bag depends on them too."""
    try:
        with open(config) as f:
            d = yaml.safe_load(f) or {}
    except (OSError, yaml.YAMLError):
        return []
    named = [(d.get('trajectory') or {}).get('waypoints_csv'), (d.get('seabed') or {}).get('image'),
             (d.get('camera') or {}).get('intrinsics_yaml')]
    return [p if os.path.isabs(p) else os.path.join(os.path.dirname(config), p) for p in named if p]


def read_landmarks(path):
    marks = []
    with open(path) as f:
        header = f.readline().strip().split(',')
        for line in f:
            if line.strip():
                row = dict(zip(header, line.strip().split(',')))
                marks.append({'id': int(row['id']), 'easting_m': float(row['easting_m']),
                              'northing_m': float(row['northing_m']), 'size_m': float(row.get('size_m', 0.3))})
    # An out-and-back puts landmark i and count-1-i on the same spot: measure each spot once.
    unique = []
    for m in marks:
        if not any(math.hypot(m['easting_m'] - u['easting_m'], m['northing_m'] - u['northing_m']) < 0.05
                   for u in unique):
            unique.append(m)
    return unique


def count_images(bag_path):
    """(image count, topic, sorted image stamps in s) of a bag."""
    import rosbag
    with rosbag.Bag(bag_path) as bag:
        for topic in IMAGE_TOPICS:
            n = bag.get_message_count(topic_filters=[topic])
            if n:
                stamps = sorted(m.header.stamp.to_sec() for _, m, _ in bag.read_messages(topics=[topic]))
                return n, topic, stamps
    return 0, None, []


# ---------------------------------------------------------------------------------------------------------------
# Processes.

def free_port():
    s = socket.socket()
    s.bind(('127.0.0.1', 0))
    port = s.getsockname()[1]
    s.close()
    return port


def proc_children(ppid):
    kids = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            with open('/proc/%s/stat' % entry) as f:
                fields = f.read().rsplit(')', 1)[1].split()
            if int(fields[1]) == ppid:
                with open('/proc/%s/cmdline' % entry, 'rb') as f:
                    kids.append((int(entry), f.read().replace(b'\0', b' ').decode(errors='replace')))
        except (OSError, IndexError, ValueError):
            pass
    return kids


def proc_sample(pid):
    """(VmHWM MB, VmRSS MB, CPU seconds) of a live process, or None."""
    try:
        hwm = rss = None
        with open('/proc/%d/status' % pid) as f:
            for line in f:
                if line.startswith('VmHWM:'):
                    hwm = int(line.split()[1]) / 1024.0
                elif line.startswith('VmRSS:'):
                    rss = int(line.split()[1]) / 1024.0
        with open('/proc/%d/stat' % pid) as f:
            fields = f.read().rsplit(')', 1)[1].split()
        cpu_s = (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
        if hwm is None:
            return None
        return hwm, rss, cpu_s
    except (OSError, IndexError, ValueError):
        return None


def stop(proc):
    if proc is None or proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=15)
    except Exception:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)
        except Exception:
            pass


class ChainMonitor:
    """Listens to the chain's outputs on the private master (wall-clock arrival times, covariances, diagnostics)."""

    def __init__(self):
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        self.lock = threading.Lock()
        # The monitor shares the 2 cores with the chain it measures: motions and poses (200 of each per second at
        # 8x) are kept as raw bytes with their arrival time and decoded after the replay (decoded(), rospy.AnyMsg).
        self.raw_motions = []   # (wall s, serialized exocet_msgs/ImageMotion)
        self.raw_odometry = []  # (wall s, serialized nav_msgs/Odometry)
        self.diagnostics = {}   # last key/value of the tile writer's status, and its wall time
        self.diag_history = []  # (wall s, images received)
        self.fusion_status = {}  # last key/value of the fusion's status
        self.web_status = {}     # last key/value of the web map's status
        self.web_queue_max = 0   # longest queue of GeoTIFFs waiting to be cut that the web map reported
        self.tiles = []         # exocet_msgs/Tile as dicts
        self.subs = [
            rospy.Subscriber('/mosaic/motion', rospy.AnyMsg, self.on_motion, queue_size=10000, tcp_nodelay=True),
            rospy.Subscriber('/mosaic/odometry', rospy.AnyMsg, self.on_odometry, queue_size=10000, tcp_nodelay=True),
            rospy.Subscriber('/diagnostics', DiagnosticArray, self.on_diagnostics, queue_size=100),
        ]
        try:
            from exocet_msgs.msg import Tile
            self.subs.append(rospy.Subscriber('/mosaic/tile', Tile, self.on_tile, queue_size=1000))
        except ImportError:
            pass

    def close(self):
        for s in self.subs:
            s.unregister()

    def on_motion(self, msg):
        self.raw_motions.append((time.time(), msg._buff))  # list.append is atomic: no lock on the hot path

    def on_odometry(self, msg):
        self.raw_odometry.append((time.time(), msg._buff))

    def decoded(self):
        """(motions as (wall s, failed, image stamp s), odometry as (wall s, sqrt of the largest eigenvalue of the horizontal
        position covariance)), decoded from the raw messages."""
        from exocet_msgs.msg import ImageMotion
        from nav_msgs.msg import Odometry
        motions = []
        for wall, buff in list(self.raw_motions):
            m = ImageMotion()
            m.deserialize(buff)
            motions.append((wall, bool(m.failed), m.header.stamp.to_sec()))
        odometry = []
        for wall, buff in list(self.raw_odometry):
            o = Odometry()
            o.deserialize(buff)
            c = o.pose.covariance
            cov = np.array([[c[0], c[1]], [c[6], c[7]]])
            sigma = math.sqrt(max(0.0, float(np.linalg.eigvalsh(cov).max()))) if np.all(np.isfinite(cov)) else float('nan')
            odometry.append((wall, sigma, o.header.stamp.to_sec()))
        return motions, odometry

    def on_diagnostics(self, msg):
        for status in msg.status:
            if status.name.endswith('fusion: fusion'):
                with self.lock:
                    self.fusion_status = {kv.key: kv.value for kv in status.values}
            elif status.name.endswith('web map'):
                values = {kv.key: kv.value for kv in status.values}
                with self.lock:
                    self.web_status = values
                    try:
                        self.web_queue_max = max(self.web_queue_max, int(values.get('queue length', '0')))
                    except ValueError:
                        pass
            elif 'tiles' in status.name and 'tile' in status.hardware_id:
                values = {kv.key: kv.value for kv in status.values}
                with self.lock:
                    self.diagnostics = dict(values, _summary=status.message, _wall_s=time.time())
                    try:
                        self.diag_history.append((time.time(), int(values.get('images received', '0')),
                                                  msg.header.stamp.to_sec()))
                    except ValueError:
                        pass

    def on_tile(self, msg):
        with self.lock:
            self.tiles.append({'index': msg.index, 'path': msg.geotiff_path, 'write_ms': msg.write_ms,
                               'position_sigma_m': msg.position_sigma_m, 'frames_composed': msg.frames_composed,
                               'close_reason': msg.close_reason, 'wall_s': time.time()})


class RosMaster:
    """A private roscore on a free port for the whole benchmark (rospy binds a process to one master)."""

    def __init__(self, ros_home, name):
        """name: the benchmark's node name on the master (anonymous)."""
        import rosgraph
        import rospy
        os.makedirs(ros_home, exist_ok=True)
        self.port = free_port()
        self.env = dict(os.environ)
        self.env['PATH'] = '/usr/bin:/bin:' + self.env.get('PATH', '')
        self.env['ROS_MASTER_URI'] = 'http://127.0.0.1:%d' % self.port
        self.env['ROS_HOME'] = ros_home
        os.environ.update({'ROS_MASTER_URI': self.env['ROS_MASTER_URI'], 'ROS_HOME': ros_home})
        self.core = subprocess.Popen(['roscore', '-p', str(self.port)], env=self.env, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, start_new_session=True)
        deadline = time.time() + 30
        while not rosgraph.Master('/' + name).is_online():
            if time.time() > deadline or self.core.poll() is not None:
                stop(self.core)
                raise RuntimeError('roscore did not start on port %d' % self.port)
            time.sleep(0.2)
        rospy.init_node(name, anonymous=True, disable_signals=True)
        self.master = rosgraph.Master('/' + name)
        self.initial_params = set(self.master.getParamNames())

    def reset_params(self):
        """Deletes the parameters the previous replays set (the launch files' and the nodes'): a parameter a launch
        sets only under a condition (e.g. the tile writer's odometry_topic with pose_graph:=true) or a preset key
        another preset lacks would otherwise outlive its replay on this master. roscore's own and roslaunch's stay."""
        keep = {'/roslaunch', '/run_id', '/rosdistro', '/rosversion'}
        namespaces = {'/' + name.strip('/').split('/')[0] for name in self.master.getParamNames()
                      if name not in self.initial_params}
        for ns in sorted(namespaces - keep):
            try:
                self.master.deleteParam(ns)
            except Exception:  # already gone
                pass

    def close(self):
        stop(self.core)


# ---------------------------------------------------------------------------------------------------------------
# Replays.

def run_chain(root, master, bag, rate, tiles_dir, timeout_s, launch_args=(), nodes=NODES, on_sample=None,
              sample_period_s=0.1):
    """One replay of bag through replay.launch at rate (launch_args: more KEY:=VALUE arguments, the presets among
    them); returns the raw measurements. nodes: the node names sampled in /proc (peak and current resident memory, CPU
    seconds); on_sample(wall_s, {node: (hwm_mb, rss_mb, cpu_s)}, monitor), when given, is called at each sample."""
    if os.path.isdir(tiles_dir):
        shutil.rmtree(tiles_dir)
    os.makedirs(tiles_dir)
    master.reset_params()
    port, env = master.port, master.env
    launch_log = os.path.join(tiles_dir, 'roslaunch.log')
    launch = None
    result = {'rate': rate, 'ok': False}
    try:
        monitor = ChainMonitor()
        time.sleep(1.0)
        args = ['roslaunch', '-p', str(port), '--wait', os.path.join(root, 'src', 'exocet_mosaic', 'launch', 'replay.launch'),
                'bag:=' + bag, 'output_dir:=' + tiles_dir, 'rate:=%g' % rate,
                'ground_truth:=false'] + list(launch_args)  # the ground-truth path is for rviz: not measured
        with open(launch_log, 'w') as out:
            launch = subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        samples = {}   # node -> last (hwm, rss, cpu)
        pids = {}
        start = time.time()
        while launch.poll() is None:
            if time.time() - start > timeout_s:
                result['error'] = 'the chain did not end within %.0f s' % timeout_s
                break
            # Scanning /proc costs CPU the chain needs: only until the nodes are found (again after a respawn).
            if len(pids) < len(nodes) or any(not os.path.exists('/proc/%d' % pid) for pid in pids.values()):
                for pid, cmd in proc_children(launch.pid):
                    for node in nodes:
                        if '__name:=%s ' % node in cmd + ' ':
                            pids[node] = pid
            for node, pid in pids.items():
                s = proc_sample(pid)
                if s is not None:
                    samples[node] = s
            if on_sample is not None:
                on_sample(time.time(), dict(samples), monitor)
            time.sleep(sample_period_s)
        end = time.time()
        time.sleep(0.5)
        monitor.close()
        with monitor.lock:
            motions, odometry = monitor.decoded()
            result.update({'motions': motions, 'odometry': odometry,
                           'diagnostics': dict(monitor.diagnostics), 'diag_history': list(monitor.diag_history),
                           'fusion_status': dict(monitor.fusion_status), 'web_status': dict(monitor.web_status),
                           'web_queue_max': monitor.web_queue_max,
                           'tile_msgs': list(monitor.tiles)})
        result['samples'] = samples
        result['launch_wall_s'] = end - start
        result['ok'] = 'error' not in result
    except Exception as e:  # a broken chain is reported, the other dives still run
        result['error'] = '%s: %s' % (type(e).__name__, e)
    finally:
        stop(launch)
    result['launch_log'] = launch_log
    # A node that died (not one ended by roslaunch) means a broken chain, not a slow machine.
    died = []
    try:
        with open(launch_log, errors='replace') as f:
            lines = [re.sub(r'\x1b\[[0-9;]*m', '', line).strip() for line in f]
        for i, line in enumerate(lines):
            m = re.match(r'process has died \[pid \d+, exit code (-?\d+), cmd (\S+)', line)
            if m and m.group(1) not in ('0', '-2', '-15'):
                name = os.path.basename(m.group(2))
                why = [x for x in lines[max(0, i - 8):i] if name.split('_node')[0].replace('_', ' ') in x.lower()
                       or 'error' in x.lower() or 'must be' in x]
                died.append('%s exited with code %s%s' % (name, m.group(1), (': ' + why[-1]) if why else ''))
    except OSError:
        pass
    if died:
        result['died'] = died
    return result


def last_frames_in_tiles(tiles_dir):
    """Index of the last frame in the tiles (EXOCET_LAST_FRAME): the composer numbers every frame it takes, so
    this + 1 is a lower bound of the images the tile writer processed (its last diagnostics may be stale)."""
    from osgeo import gdal
    last = -1
    for path in tile_analysis.tile_paths(tiles_dir):
        ds = gdal.Open(path)
        if ds is not None:
            try:
                last = max(last, int((ds.GetMetadata() or {}).get('EXOCET_LAST_FRAME', -1)))
            except ValueError:
                pass
        ds = None
    return last


def chain_figures(run, frames, tiles_dir=None, stamps=None, fps=25.0, nodes=NODES):
    """The chain's figures of one run_chain replay of `frames` images (fps: the bag's frame rate)."""
    motions = run.get('motions', [])
    diag = run.get('diagnostics', {})
    fig = {'rate': run['rate'], 'frames': frames, 'motions': len(motions),
           'motions_failed': sum(1 for m in motions if m[1]), 'launch_wall_s': rnd(run.get('launch_wall_s'), 1)}
    # The fusion's resets and late inputs (a chain too slow for the rate loses its filter's history, not frames) and
    # how far the web map fell behind, from their last /diagnostics.
    for key, name in (('resets', 'fusion_resets'), ('late inputs dropped', 'fusion_late_inputs_dropped')):
        try:
            fig[name] = int(run.get('fusion_status', {})[key])
        except (KeyError, ValueError):
            pass
    if run.get('web_status'):
        fig['web_map_queue_length_max'] = run.get('web_queue_max')
        try:
            fig['web_map_max_cut_latency_ms'] = float(run['web_status'].get('max cut latency (ms)', 'nan'))
        except ValueError:
            pass
    try:
        received = int(diag.get('images received', '-1'))
    except ValueError:
        received = -1
    fig['tile_writer_images_received_last_diagnostics'] = received
    # Its diagnostics follow ROS time: in a replay they stop with the bag's clock, so the last status is not the
    # final count. Frames the bag had published by that status's stamp and the node had not received are drops
    # (but for the few in flight: a tenth of a second of replay).
    history = run.get('diag_history', [])
    if stamps and history and history[-1][2] > 0:
        import bisect
        expected = bisect.bisect_right(stamps, history[-1][2])
        fig['tile_writer_images_published_by_last_diagnostics'] = expected
        in_flight = int(math.ceil(run['rate'] * fps * 0.1))
        fig['frames_dropped_tile_writer_by_last_diagnostics'] = max(0, expected - received - in_flight)
    composed_last = last_frames_in_tiles(tiles_dir) if tiles_dir else -1
    fig['tile_writer_last_frame_in_tiles'] = composed_last
    if composed_last + 1 > received:
        fig['tile_writer_diagnostics_stale'] = True  # the node stopped publishing them before its last images
    received = max(received, composed_last + 1)
    fig['tile_writer_images_received'] = received
    for key in ('frames composed', 'frames skipped (no pose)', 'frames skipped (no chain, no pose)',
                'frames released incomplete (timeout)', 'images rejected', 'registration gaps bridged by the navigation',
                'navigation jumps', 'tiles written', 'tiles lost', 'write failures', 'tiles queued (most at once)',
                'composition waits for the writer', 'composition wait for the writer (s)'):
        if key in diag:
            fig['tile_writer_' + re.sub(r'[^a-z0-9]+', '_', key).strip('_')] = diag[key]
    dropped_registration = max(0, frames - 1 - len(motions))
    # The frames after the last status: the composer's last frame bounds them (up to one key-frame interval).
    dropped_writer = max(0, frames - received) if received >= 0 else None
    if 'frames_dropped_tile_writer_by_last_diagnostics' in fig and dropped_writer is not None:
        # Both are upper bounds: the status counts images still queued in the node as missing, the tiles miss the
        # frames after the last key frame. Their minimum is the estimate.
        fig['frames_not_seen_in_tiles'] = dropped_writer
        dropped_writer = min(dropped_writer, fig['frames_dropped_tile_writer_by_last_diagnostics'])
    fig['frames_dropped_registration'] = dropped_registration
    fig['frames_dropped_tile_writer'] = dropped_writer
    # The fusion publishes one fused pose per image motion once it knows where it is (its first position fix):
    # a motion from then on without the pose of the same stamp is a frame left unplaced in the tiles.
    odometry_stamps = {round(o[2], 6) for o in run.get('odometry', [])}
    first_pose = min(odometry_stamps) if odometry_stamps else float('inf')
    fig['frames_before_first_pose'] = sum(1 for m in motions if m[2] < first_pose)
    fig['frames_dropped_fusion'] = sum(1 for m in motions if m[2] >= first_pose and round(m[2], 6) not in odometry_stamps)
    fig['frames_dropped'] = max(dropped_registration, fig['frames_dropped_fusion'],
                                dropped_writer if dropped_writer is not None else frames)
    if len(motions) >= 2:
        first = motions[0][0]
        # The fusion holds the last ~0.3 s of the bag (its reorder delay) until its inputs have been silent for 0.5 s
        # of wall time: the poses released then are the end of the replay's latency, not its throughput.
        odometry = run.get('odometry', [])
        flowing = [o for o in odometry if o[0] <= motions[-1][0] + 0.5]
        last = max(motions[-1][0], flowing[-1][0] if flowing else 0.0)
        fig['chain_fps'] = rnd(frames / (last - first), 1)
        fig['chain_end_of_input_flush_s'] = rnd(odometry[-1][0] - last, 2) if odometry else None
        # Lag of the outputs behind the replay: arrival minus where the bag's clock (at the replay rate) puts the image,
        # relative to the first motion. A lag that settles is the pipeline's latency; one that keeps growing is a chain
        # slower than the replay. Sampled every 50 messages, and the last.
        def lag(msg):
            return (msg[0] - motions[0][0]) - (msg[2] - motions[0][2]) / run['rate']
        lags = [lag(m) for m in motions]
        fig['registration_lag_s'] = [rnd(x, 3) for x in lags[::50]] + [rnd(lags[-1], 3)]
        fig['registration_lag_max_s'] = rnd(max(lags), 3)
        if flowing:
            lags = [lag(o) for o in flowing]
            fig['fusion_lag_s'] = [rnd(x, 3) for x in lags[::50]] + [rnd(lags[-1], 3)]
            fig['fusion_lag_max_s'] = rnd(max(lags), 3)
        # The tile writer's diagnostics (1 Hz) say when it had received every image: an upper bound of its lag.
        done = [h[0] for h in run.get('diag_history', []) if h[1] >= received > 0]
        if done:
            fig['tile_writer_done_after_s'] = rnd(done[0] - first, 1)
    samples = run.get('samples', {})
    for node in nodes:
        if node in samples:
            fig['peak_rss_mb_' + node] = rnd(samples[node][0], 1)
            fig['cpu_s_' + node] = rnd(samples[node][2], 1)
    if samples:
        fig['peak_rss_mb'] = rnd(max(s[0] for s in samples.values()), 1)
        cpu = sum(s[2] for s in samples.values())
        fig['chain_cpu_s'] = rnd(cpu, 1)
        if fig.get('launch_wall_s'):
            fig['chain_cpu_cores'] = rnd(cpu / fig['launch_wall_s'], 2)
    sig = [o[1] for o in run.get('odometry', []) if math.isfinite(o[1])]
    fig['position_sigma_odometry_m'] = rnd(float(np.median(sig)) if sig else None)
    fig['odometry_messages'] = len(run.get('odometry', []))
    fig['tile_write_ms'] = {os.path.basename(t['path']): rnd(t['write_ms'], 1) for t in run.get('tile_msgs', [])}
    writes = [t['write_ms'] for t in run.get('tile_msgs', [])]
    if writes:
        fig['tile_write_ms_median'] = rnd(float(np.median(writes)), 1)
        fig['tile_write_ms_max'] = rnd(max(writes), 1)
    return fig
