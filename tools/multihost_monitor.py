#!/usr/bin/env python3
"""Records when each image's registration reaches the surface (tools/multihost-test.sh): /mosaic/motion, published
by the registration for every image it receives, so that the monitor adds no traffic on the umbilical. Writes
wall_s,stamp_s per message to --output until interrupted."""
import argparse
import time

import rospy
from exocet_msgs.msg import ImageMotion


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--output', required=True)
    args = parser.parse_args(rospy.myargv()[1:])
    rospy.init_node('multihost_monitor')
    out = open(args.output, 'w', buffering=1)
    out.write('wall_s,stamp_s\n')
    rospy.Subscriber('/mosaic/motion', ImageMotion,
                     lambda m: out.write('%.6f,%.6f\n' % (time.time(), m.header.stamp.to_sec())), queue_size=1000)
    rospy.spin()
    out.close()


if __name__ == '__main__':
    main()
