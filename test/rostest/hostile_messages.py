#!/usr/bin/python3
"""Hostile messages into the running detectors and the projection (issue 15): the issue's
crashing clouds and images are published into one nodelet manager (no respawn); the manager must
keep its pid, and a good message sent afterwards must still be processed."""
import os
import struct
import sys
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from sensor_msgs.msg import CameraInfo, Image, PointCloud2, PointField

MANAGER = "/hostile_manager"


def cloud(stamp, row_step=None, z_offset=8, big_endian=False, declared=None):
    """A flat wall 3 m ahead; x y z float32 (the board is not in it: any output will do).
    `declared` = (width, height) written into the header, not matching the data."""
    width, height = 64, 4
    fields = [PointField("x", 0, PointField.FLOAT32, 1), PointField("y", 4, PointField.FLOAT32, 1),
              PointField("z", z_offset, PointField.FLOAT32, 1)]
    fmt = ">fff" if big_endian else "<fff"
    data = b"".join(struct.pack(fmt, 3.0, 0.01 * c, 0.05 * r) for r in range(height) for c in range(width))
    msg = PointCloud2()
    msg.header.stamp = stamp
    msg.header.frame_id = "lidar"
    msg.height, msg.width, msg.fields = height, width, fields
    msg.is_bigendian, msg.point_step = big_endian, 12
    msg.row_step = width * 12 if row_step is None else row_step
    msg.data, msg.is_dense = data, True
    if declared:
        msg.width, msg.height = declared
    return msg


def image(stamp, width=64, height=48, step=None, encoding="mono8", data_len=None):
    msg = Image()
    msg.header.stamp = stamp
    msg.header.frame_id = "camera"
    msg.width, msg.height, msg.encoding = width, height, encoding
    msg.step = width if step is None else step
    msg.data = bytes(width * height if data_len is None else data_len)
    return msg


def info(stamp, width=64, height=48, fx=50.0):
    msg = CameraInfo()
    msg.header.stamp = stamp
    msg.header.frame_id = "camera"
    msg.width, msg.height = width, height
    msg.distortion_model = "plumb_bob"
    msg.D = [0.0] * 5
    msg.K = [fx, 0, width / 2.0, 0, fx, height / 2.0, 0, 0, 1]
    msg.P = [fx, 0, width / 2.0, 0, 0, fx, height / 2.0, 0, 0, 0, 1, 0]
    return msg


class HostileMessages(unittest.TestCase):
    def setUp(self):
        self.counts = {"lidar_board": 0, "camera_board": 0}
        rospy.Subscriber("lidar_board", rospy.AnyMsg, lambda _: self.bump("lidar_board"))
        rospy.Subscriber("camera_board", rospy.AnyMsg, lambda _: self.bump("camera_board"))
        rospy.Subscriber("colored_cloud", PointCloud2, lambda _: None)  # wakes the lazy projection
        self.cloud_pub = rospy.Publisher("points", PointCloud2, queue_size=20)
        self.image_pub = rospy.Publisher("camera/image_raw", Image, queue_size=20)
        self.info_pub = rospy.Publisher("camera/camera_info", CameraInfo, queue_size=20)
        deadline = time.time() + 30
        # The nodelets share the manager's process: one connection serves all of them.
        while time.time() < deadline and (self.cloud_pub.get_num_connections() < 1 or
                                          self.image_pub.get_num_connections() < 1):
            time.sleep(0.1)
        time.sleep(3.0)  # the other lazy nodelets subscribe on the same connection
        uri = rosgraph.Master(rospy.get_name()).lookupNode(MANAGER)
        self.pid = xmlrpc.client.ServerProxy(uri).getPid(rospy.get_name())[2]

    def bump(self, key):
        self.counts[key] += 1

    def send(self, cloud_msg, image_msg, info_msg):
        self.cloud_pub.publish(cloud_msg)
        self.info_pub.publish(info_msg)
        self.image_pub.publish(image_msg)
        time.sleep(0.3)

    def alive(self):
        try:
            os.kill(self.pid, 0)
            return True
        except OSError:
            return False

    def test_manager_survives_and_keeps_working(self):
        self.assertGreaterEqual(self.cloud_pub.get_num_connections(), 1, "the manager never subscribed")
        t = rospy.Time(100)
        hostile = [
            (cloud(t, row_step=0x7fffffff), image(t, width=16, height=65537, step=65536, data_len=16)),
            (cloud(t, row_step=64 * 12 + 4), image(t, step=10)),
            (cloud(t, z_offset=10), image(t, data_len=100)),
            (cloud(t, declared=(0x10000, 0x10000)), image(t, encoding="32FC1")),
            (cloud(t, row_step=1), image(t, encoding="mono16", step=64)),
        ]
        for k, (c, i) in enumerate(hostile):
            stamp = rospy.Time(100 + k)
            c.header.stamp = i.header.stamp = stamp
            self.send(c, i, info(stamp, width=i.width, height=i.height))
            self.send(cloud(stamp), i, info(stamp, fx=float("nan")))
        self.assertTrue(self.alive(), "the nodelet manager died")
        before = dict(self.counts)
        for k in range(3):
            stamp = rospy.Time(200 + k)
            self.send(cloud(stamp), image(stamp), info(stamp))
            self.send(cloud(stamp, big_endian=True), image(stamp), info(stamp))
        deadline = time.time() + 10
        while time.time() < deadline and (self.counts["lidar_board"] <= before["lidar_board"] or
                                          self.counts["camera_board"] <= before["camera_board"]):
            time.sleep(0.1)
        self.assertTrue(self.alive(), "the nodelet manager died")
        self.assertGreater(self.counts["lidar_board"], before["lidar_board"], "no LidarBoard after the hostile clouds")
        self.assertGreater(self.counts["camera_board"], before["camera_board"], "no CameraBoard after the hostile images")


if __name__ == "__main__":
    rospy.init_node("hostile_messages")
    rostest.rosrun("board_calib", "hostile_messages", HostileMessages, sys.argv)
