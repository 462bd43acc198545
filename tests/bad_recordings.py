"""Bad recordings made from a good dive bag, for the fault tests (check_bad_recordings_replay.py,
check_truncated_bag_replay.py).

FAULTS lists what goes wrong and when (seconds after the bag's start): each fault spans a short window of the dive, the
windows apart so that each one's effect can be told from the others'. write_faulty_bag() copies the bag with every
fault applied; truncate_bag() cuts a bag file in the middle, as a recorder that died (or a full disk) leaves it.
"""
import collections
import os

import cv2
import numpy as np
import rosbag
import rospy

Fault = collections.namedtuple('Fault', 'name start_s end_s what')

FAULTS = [
    Fault('corrupt_jpeg', 10.0, 12.0, 'every JPEG of the window corrupt: its header kept, the rest of its bytes noise'),
    Fault('image_size', 20.0, 22.0, 'the images of the window at half size (360x288), camera_info unchanged'),
    Fault('nan_navigation', 30.0, 32.0, 'NaN in the dead reckoning, the attitude, the altimeter and a USBL fix'),
    Fault('backwards_navigation', 40.0, 42.0, 'the dead reckoning and the attitude stamped 3 s back in the window'),
    Fault('duplicated_stamps', 50.0, 52.0, 'every image, camera_info and dead reckoning of the window sent twice'),
    Fault('camera_info_change', 60.0, None, 'camera_info from then on: focal length +5 % and another distortion'),
]

TOPICS = ['/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry', '/nav/usbl', '/nav/imu',
          '/nav/altitude', '/nav/datum', '/nav/depth', '/tf_static', '/ground_truth/odometry']


def fault_named(name):
    return next(f for f in FAULTS if f.name == name)


def _in(fault, dive_s):
    return dive_s >= fault.start_s and (fault.end_s is None or dive_s < fault.end_s)


def _corrupt(msg, rng):
    data = bytearray(msg.data)
    keep = min(len(data), 600)  # SOI and the tables: the header still says JPEG and its size
    data[keep:] = rng.integers(0, 256, len(data) - keep, dtype=np.uint8).tobytes()
    msg.data = bytes(data)


def _half_size(msg):
    image = cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
    small = cv2.resize(image, (image.shape[1] // 2, image.shape[0] // 2), interpolation=cv2.INTER_AREA)
    ok, encoded = cv2.imencode('.jpg', small, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    msg.data = encoded.tobytes()


def write_faulty_bag(source, destination, faults=FAULTS, seed=5):
    """Copies `source` to `destination` with `faults` applied; returns the bag's start time (s)."""
    rng = np.random.default_rng(seed)
    active = {f.name: f for f in faults}
    back = rospy.Duration(3.0)
    with rosbag.Bag(source) as bag, rosbag.Bag(destination, 'w') as out:
        start = bag.get_start_time()
        for topic, msg, t, header in bag.read_messages(topics=TOPICS, return_connection_header=True):
            dive_s = t.to_sec() - start
            repeats = 1
            if topic == '/camera/image_raw/compressed':
                if 'corrupt_jpeg' in active and _in(active['corrupt_jpeg'], dive_s):
                    _corrupt(msg, rng)
                if 'image_size' in active and _in(active['image_size'], dive_s):
                    _half_size(msg)
            if topic == '/camera/camera_info' and 'camera_info_change' in active and \
                    _in(active['camera_info_change'], dive_s):
                k = list(msg.K)
                k[0] *= 1.05
                k[4] *= 1.05
                msg.K = k
                msg.P = [k[0], 0, k[2], 0, 0, k[4], k[5], 0, 0, 0, 1, 0]
                msg.D = [d * 0.5 for d in msg.D] if any(msg.D) else [-0.05, 0.01, 0.0, 0.0, 0.0]
            if 'nan_navigation' in active and _in(active['nan_navigation'], dive_s):
                if topic == '/nav/odometry':
                    msg.pose.pose.position.x = float('nan')
                elif topic == '/nav/imu':
                    msg.orientation.w = float('nan')
                elif topic == '/nav/altitude':
                    msg.range = float('nan')
                elif topic == '/nav/usbl':
                    msg.latitude = float('nan')
            if 'backwards_navigation' in active and _in(active['backwards_navigation'], dive_s) and \
                    topic in ('/nav/odometry', '/nav/imu'):
                msg.header.stamp = msg.header.stamp - back
            if 'duplicated_stamps' in active and _in(active['duplicated_stamps'], dive_s) and \
                    topic in ('/camera/image_raw/compressed', '/camera/camera_info', '/nav/odometry'):
                repeats = 2
            for _ in range(repeats):
                out.write(topic, msg, t, connection_header=header)  # latched topics stay latched
    return start


def truncate_bag(source, destination, fraction=0.5):
    """Copies the first `fraction` of the bag file's bytes: no index, a chunk cut in the middle."""
    size = os.path.getsize(source)
    with open(source, 'rb') as f_in, open(destination, 'wb') as f_out:
        remaining = int(size * fraction)
        while remaining > 0:
            block = f_in.read(min(remaining, 1 << 20))
            if not block:
                break
            f_out.write(block)
            remaining -= len(block)
