#!/usr/bin/python3
"""Republishes the first image / camera_info / cloud triple of a bag with fresh stamps, at a
fixed rate: a light, deterministic live source for the headless rviz check (playing the bz2
recording in real time needs more CPU than a loaded CI machine may have).

usage: publish_frame.py BAG IMAGE_TOPIC INFO_TOPIC CLOUD_TOPIC [RATE_HZ]
Publishes on image_raw, camera_info and points (relative names).
"""
import sys

import rosbag
import rospy
from sensor_msgs.msg import CameraInfo, Image, PointCloud2


def main():
    argv = rospy.myargv(sys.argv)
    if len(argv) < 5:
        sys.exit(__doc__)
    bag_path, image_topic, info_topic, cloud_topic = argv[1:5]
    rate_hz = float(argv[5]) if len(argv) > 5 else 1.0
    first = {}
    with rosbag.Bag(bag_path) as bag:
        for topic, msg, _ in bag.read_messages(topics=[image_topic, info_topic, cloud_topic]):
            first.setdefault(topic, msg)
            if len(first) == 3:
                break
    if len(first) != 3:
        sys.exit("bag lacks one of %s %s %s" % (image_topic, info_topic, cloud_topic))
    rospy.init_node("publish_frame")
    pubs = {image_topic: rospy.Publisher("image_raw", Image, queue_size=1),
            info_topic: rospy.Publisher("camera_info", CameraInfo, queue_size=1),
            cloud_topic: rospy.Publisher("points", PointCloud2, queue_size=1)}
    # Keep the recorded offset between the cloud and the image stamps.
    offsets = {t: first[t].header.stamp - first[image_topic].header.stamp for t in first}
    rate = rospy.Rate(rate_hz)
    while not rospy.is_shutdown():
        now = rospy.Time.now()
        for topic, msg in first.items():
            msg.header.stamp = now + offsets[topic]
            pubs[topic].publish(msg)
        rate.sleep()


if __name__ == "__main__":
    main()
