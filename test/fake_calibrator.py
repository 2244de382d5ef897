#!/usr/bin/python3
"""A stand-in for the calibrator nodelet's interface, recording every service call.

usage: fake_calibrator.py NAMESPACE CALLS.jsonl

Offers NAMESPACE/{capture,drop_view,calibrate,reset,save_session,load_session} with the real
service types, publishes the calibrator's /diagnostics status (same hardware id and keys as
include/board_calib/calibrator_status.h) and the latched calibration_result in the parent
namespace. Each call is appended to CALLS.jsonl as {"service": ..., "request": {...}}.
Views are plain ids; calibrate returns a fixed residual per view id so a test can check what
the panel shows.
"""
import json
import sys
import threading

import rospy
from board_calib.msg import CalibrationResult
from board_calib.srv import (Calibrate, CalibrateResponse, DropView, DropViewResponse, SessionFile,
                             SessionFileResponse)
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_srvs.srv import Trigger, TriggerResponse

HARDWARE_ID = "board_calib calibrator"
STATUS_NAME = "calibration session"
STATUS_PERIOD_S = 0.5
# calibrate answers this late, like a real solve, so the test sees the GUI stay responsive.
SOLVE_TIME_S = 5.0


def view_mlre_px(view_id):
    """The residual the fake reports for a view: view 3 is the outlier."""
    return 9.0 if view_id == 3 else 1.0 + 0.1 * view_id


def view_plane_rms_mm(view_id):
    return 10.0 + view_id


class FakeCalibrator:
    def __init__(self, ns, calls_path):
        self.ns = ns
        self.calls_path = calls_path
        self.lock = threading.Lock()
        self.views = []
        self.next_id = 0
        self.last_event = "waiting for features"
        parent = ns.rsplit("/", 1)[0] or "/"
        self.result_pub = rospy.Publisher(parent.rstrip("/") + "/calibration_result", CalibrationResult,
                                          queue_size=1, latch=True)
        self.diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        self.services = [
            rospy.Service(ns + "/capture", Trigger, self.capture),
            rospy.Service(ns + "/drop_view", DropView, self.drop_view),
            rospy.Service(ns + "/calibrate", Calibrate, self.calibrate),
            rospy.Service(ns + "/reset", Trigger, self.reset),
            rospy.Service(ns + "/save_session", SessionFile, self.save_session),
            rospy.Service(ns + "/load_session", SessionFile, self.load_session),
        ]
        rospy.Timer(rospy.Duration(STATUS_PERIOD_S), self.publish_status)

    def record(self, service, request):
        with open(self.calls_path, "a") as f:
            f.write(json.dumps({"service": service, "request": request}) + "\n")

    def capture(self, _req):
        self.record("capture", {})
        with self.lock:
            view_id = self.next_id
            self.next_id += 1
            self.views.append(view_id)
            self.last_event = "capture: view %d accepted (forced)" % view_id
            return TriggerResponse(True, "view %d accepted (forced)" % view_id)

    def drop_view(self, req):
        self.record("drop_view", {"view_id": req.view_id})
        with self.lock:
            if req.view_id not in self.views:
                return DropViewResponse(False, "no view %d" % req.view_id)
            self.views.remove(req.view_id)
            return DropViewResponse(True, "view %d dropped" % req.view_id)

    def calibrate(self, req):
        self.record("calibrate", {"method": req.method, "use_initial_guess": req.use_initial_guess})
        with self.lock:
            views = list(self.views)
        rospy.sleep(SOLVE_TIME_S)
        r = CalibrationResult()
        r.header.stamp = rospy.Time.now()
        r.header.frame_id = "os1_lidar"
        r.success = len(views) >= 3
        r.method = "pbpc" if req.method in ("", "all") else req.method
        r.camera_frame, r.lidar_frame = "camera", "os1_lidar"
        r.camera_T_lidar.translation.x, r.camera_T_lidar.translation.y = 0.1, -0.2
        r.camera_T_lidar.translation.z = 0.05
        r.camera_T_lidar.rotation.w = 1.0
        r.views_used = len(views)
        r.mlre_px = 2.5
        r.plane_rms_mm = 12.0
        r.stddev_translation_m = [0.003, 0.004, 0.0]
        r.stddev_rotation_deg = [0.1, 0.0, 0.0]
        r.view_ids = views
        r.view_mlre_px = [view_mlre_px(v) for v in views]
        r.view_plane_rms_mm = [view_plane_rms_mm(v) for v in views]
        if not r.success:
            r.reason = "needs at least 3 views"
            r.verdict, r.verdict_reason = "failed", r.reason
            return CalibrateResponse(success=False, message="calibration failed: " + r.reason, result=r)
        r.verdict = "doubtful"
        r.verdict_reason = "view 3 has an edge 9 px off"
        self.result_pub.publish(r)
        return CalibrateResponse(success=True, message="%s with %d views\nmore lines" % (r.method, len(views)),
                                 result=r)

    def reset(self, _req):
        self.record("reset", {})
        with self.lock:
            n = len(self.views)
            self.views = []
            return TriggerResponse(True, "session reset (%d views dropped)" % n)

    def save_session(self, req):
        self.record("save_session", {"path": req.path})
        with self.lock:
            with open(req.path, "w") as f:
                json.dump({"views": self.views, "next_id": self.next_id}, f)
            return SessionFileResponse(True, "saved %d views to %s" % (len(self.views), req.path), len(self.views))

    def load_session(self, req):
        self.record("load_session", {"path": req.path})
        with self.lock:
            try:
                with open(req.path) as f:
                    data = json.load(f)
            except (OSError, ValueError) as e:
                return SessionFileResponse(False, "cannot read %s: %s" % (req.path, e), len(self.views))
            self.views, self.next_id = data["views"], data["next_id"]
            return SessionFileResponse(True, "loaded %d views from %s" % (len(self.views), req.path),
                                       len(self.views))

    def publish_status(self, _event):
        with self.lock:
            views = list(self.views)
            event = self.last_event
        s = DiagnosticStatus()
        s.level = DiagnosticStatus.OK if len(views) >= 3 else DiagnosticStatus.WARN
        s.name = "fake_manager: " + STATUS_NAME
        s.hardware_id = HARDWARE_ID
        s.message = "%d views collected" % len(views) if len(views) >= 3 else "collecting views (%d)" % len(views)
        values = [("services", self.ns), ("views", str(len(views))), ("view ids", " ".join(map(str, views))),
                  ("lidar board", "found"), ("camera board", "not found: no line hypothesis"),
                  ("board motion", "board still for +-0.25 s (5 LiDAR frames)"), ("last event", event),
                  ("advice 1", "tilt the board more (span 12 deg)")]
        s.values = [KeyValue(k, v) for k, v in values]
        # A second calibrator in another namespace: the panel must ignore it.
        other = DiagnosticStatus(level=DiagnosticStatus.ERROR, name="other: " + STATUS_NAME,
                                 hardware_id=HARDWARE_ID, message="the other calibrator",
                                 values=[KeyValue("services", "/other_calibrator"), KeyValue("views", "99")])
        array = DiagnosticArray()
        array.header.stamp = rospy.Time.now()
        array.status = [other, s]
        self.diag_pub.publish(array)


if __name__ == "__main__":
    args = rospy.myargv(sys.argv)
    if len(args) != 3:
        sys.exit(__doc__)
    rospy.init_node("fake_calibrator", anonymous=True)
    FakeCalibrator(args[1], args[2])
    rospy.spin()
