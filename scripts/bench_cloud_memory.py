#!/usr/bin/python3
"""Memory under load: N clouds through the cloud detector nodelet, RSS of the manager sampled.

Starts its own master, a nodelet manager with the cloud_board_detector (launch files of this
package), republishes the clouds of a bag N times at a fixed rate, counts the LidarBoard outputs
and prints the manager's RSS every 10 % of the run. Run inside the built environment:

  scripts/env.sh /usr/bin/python3 scripts/bench_cloud_memory.py \
      --bag ../shared/data/basler_os1_plain/session.bag --topic /os1/points \
      --target ../shared/data/basler_os1_plain/target.yaml --clouds 1000 --rate 10
"""
import argparse
import os
import signal
import socket
import subprocess
import sys
import time


def free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def rss_kib(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bag", required=True)
    ap.add_argument("--topic", required=True)
    ap.add_argument("--target", required=True)
    ap.add_argument("--clouds", type=int, default=1000)
    ap.add_argument("--rate", type=float, default=10.0, help="clouds per second")
    args = ap.parse_args()

    port = free_port()
    os.environ["ROS_MASTER_URI"] = "http://localhost:%d" % port
    procs = []
    try:
        procs.append(subprocess.Popen(["roscore", "-p", str(port)], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        time.sleep(3)
        procs.append(subprocess.Popen(
            ["roslaunch", "--wait", "board_calib", "cloud_board_detector.launch", "start_manager:=true",
             "manager:=bench_manager", "points:=/bench/points", "target_file:=" + os.path.abspath(args.target)],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))

        import rosbag
        import rospy

        rospy.init_node("bench_cloud_memory", anonymous=True)
        clouds = [m for _, m, _ in rosbag.Bag(args.bag).read_messages(topics=[args.topic])]
        if not clouds:
            sys.exit("no message on %s in %s" % (args.topic, args.bag))
        outputs = {"n": 0}

        def on_board(_):
            outputs["n"] += 1

        # AnyMsg: counting needs no generated Python messages.
        rospy.Subscriber("lidar_board", rospy.AnyMsg, on_board, queue_size=100)
        pub = rospy.Publisher("/bench/points", type(clouds[0]), queue_size=5)
        deadline = time.time() + 60
        while pub.get_num_connections() == 0 and time.time() < deadline:
            time.sleep(0.1)
        if pub.get_num_connections() == 0:
            sys.exit("the detector never subscribed")
        import rosgraph
        import xmlrpc.client
        uri = rosgraph.Master("/bench_cloud_memory").lookupNode("/bench_manager")
        pid = xmlrpc.client.ServerProxy(uri).getPid("/bench_cloud_memory")[2]
        print("manager pid %d, %d clouds of %s (%d distinct), %.1f Hz" % (pid, args.clouds, args.bag, len(clouds),
                                                                       args.rate))
        print("%8s %10s %10s" % ("sent", "outputs", "RSS MiB"))
        period = 1.0 / args.rate
        samples = []
        start = time.time()
        for i in range(args.clouds):
            msg = clouds[i % len(clouds)]
            msg.header.stamp = rospy.Time.now()
            pub.publish(msg)
            next_time = start + (i + 1) * period
            time.sleep(max(0.0, next_time - time.time()))
            if (i + 1) % max(1, args.clouds // 10) == 0:
                rss = rss_kib(pid) / 1024.0
                samples.append(rss)
                print("%8d %10d %10.1f" % (i + 1, outputs["n"], rss))
        time.sleep(2)
        print("outputs %d / %d clouds; RSS first %.1f MiB, last %.1f MiB, max %.1f MiB"
              % (outputs["n"], args.clouds, samples[0], samples[-1], max(samples)))
    finally:
        for p in reversed(procs):
            try:
                os.killpg(p.pid, signal.SIGINT)
                p.wait(timeout=20)
            except Exception:
                os.killpg(p.pid, signal.SIGKILL)


if __name__ == "__main__":
    main()
