#!/usr/bin/python3
"""Checks every camera<->LiDAR pair of an MSG-Cal result file against simulate_bag's truth file.

usage: check_rig_result.py RESULT.yaml TRUTH.yaml MAX_ROT_DEG MAX_TRANS_M [MAX_SIGMAS]
The truth pair is derived from the truth's sensor poses (independent of the tool's comparison).
With MAX_SIGMAS, each pair's translation error on every axis must also lie within that many of
the pair's own reported 1 sigma (an honest uncertainty, whatever the verdict).
"""
import math
import sys

import yaml


def mat(entry):
    m = entry["matrix"]
    return [m[0:4], m[4:8], m[8:12], m[12:16]]


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def inv(t):
    r = [[t[j][i] for j in range(3)] for i in range(3)]
    p = [-sum(r[i][k] * t[k][3] for k in range(3)) for i in range(3)]
    return [r[0] + [p[0]], r[1] + [p[1]], r[2] + [p[2]], [0, 0, 0, 1]]


def main():
    if len(sys.argv) not in (5, 6):
        print(__doc__)
        return 2
    max_sigmas = float(sys.argv[5]) if len(sys.argv) == 6 else None
    result = yaml.safe_load(open(sys.argv[1]))
    truth = yaml.safe_load(open(sys.argv[2]))
    max_rot, max_trans = float(sys.argv[3]), float(sys.argv[4])
    poses = {s["frame"]: mat(s["reference_T_sensor"]) for s in truth["sensors"]}
    pairs = result.get("pairs") or []
    truth_pairs = sum(1 for c in poses for l in poses
                      if any(s["frame"] == c and s["kind"] == "camera" for s in truth["sensors"])
                      and any(s["frame"] == l and s["kind"] == "lidar" for s in truth["sensors"]))
    if len(pairs) != truth_pairs:
        print(f"result has {len(pairs)} pairs, truth has {truth_pairs}")
        return 1
    failed = False
    for p in pairs:
        est = mat(p["camera_T_lidar"])
        gt = mul(inv(poses[p["camera_frame"]]), poses[p["lidar_frame"]])
        d = mul(inv(gt), est)
        cos = max(-1.0, min(1.0, (d[0][0] + d[1][1] + d[2][2] - 1.0) / 2.0))
        rot = math.degrees(math.acos(cos))
        trans = math.sqrt(sum((est[i][3] - gt[i][3]) ** 2 for i in range(3)))
        bad = rot > max_rot or trans > max_trans
        sigmas = ""
        if max_sigmas is not None:
            sigma = (p.get("stddev") or {}).get("translation_m")
            if not sigma or len(sigma) != 3 or min(sigma) <= 0:
                sigmas, bad = ", no 1 sigma", True
            else:
                worst = max(abs(est[i][3] - gt[i][3]) / sigma[i] for i in range(3))
                sigmas = f", {worst:.1f} sigma on its worst axis"
                bad |= worst > max_sigmas
        failed |= bad
        print(f"{p['camera_frame']} <- {p['lidar_frame']}: {rot:.3f} deg, {trans * 1e3:.1f} mm{sigmas}"
              f"{'  FAIL' if bad else ''}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
