#!/usr/bin/python3
"""The offline answer to a doubtful verdict: drop the views it names, solve again.

usage: check_drop_views.py CALIBRATE_BAG BAG_DIR WORK_DIR
BAG_DIR holds simulate_bag's session.bag, session.target.yaml and session.truth.yaml.

The session is saved, then four of its views get LiDAR boards moved 4 cm along the LiDAR's z
(the board moved between the sensors' frames, by less than the consistency check's allowance).
Asserted:
  * the corrupted session is doubtful and names exactly the four views (views_to_check);
  * --drop-views with those ids gives a good verdict on the 16 views kept, within 0.2 deg / 1 cm of
    the truth (the plain-board end-to-end test's bound), and the result file says what was left out;
  * ids the session does not hold, dropping every view, and overwriting the loaded session with
    fewer views are usage errors (exit 2) naming the problem; the loaded file is unchanged.
"""
import hashlib
import os
import subprocess
import sys

import yaml

CORRUPTED = [3, 7, 11, 15]
SHIFT_M = (0.0, 0.0, 0.04)


def run(args, expect):
    p = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if p.returncode != expect:
        sys.exit("FAIL: %s\nexit %d, expected %d\n%s%s" % (" ".join(args), p.returncode, expect,
                                                            p.stdout, p.stderr))
    return p.stdout + p.stderr


def shift(values):
    return [v + SHIFT_M[i % 3] for i, v in enumerate(values)]


def corrupt(src, dst):
    session = yaml.safe_load(open(src))
    for view in session["views"]:
        if view["id"] not in CORRUPTED:
            continue
        lidar = view["lidar"]
        lidar["board_points"] = shift(lidar["board_points"])
        normal = lidar["plane"][:3]
        lidar["plane"][3] -= sum(n * s for n, s in zip(normal, SHIFT_M))
        for edge in lidar.get("edges", []):
            for key in ("line_point", "corner", "points"):
                if key in edge:
                    edge[key] = shift(edge[key])
    with open(dst, "w") as f:
        yaml.safe_dump(session, f, default_flow_style=None, width=1 << 30)


def digest(path):
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    tool, bag_dir, work = sys.argv[1:]
    os.makedirs(work, exist_ok=True)
    saved = os.path.join(work, "session.yaml")
    bad = os.path.join(work, "corrupted.yaml")
    truth = os.path.join(bag_dir, "session.truth.yaml")
    run([tool, "--quiet", "--bag", os.path.join(bag_dir, "session.bag"), "--target",
         os.path.join(bag_dir, "session.target.yaml"), "--image-topic", "/camera/image_raw",
         "--camera-info-topic", "/camera/camera_info", "--cloud-topic", "/lidar/points",
         "--method", "pbpc", "--save-session", saved], 0)
    corrupt(saved, bad)

    doubtful = os.path.join(work, "doubtful.yaml")
    run([tool, "--quiet", "--load-session", bad, "--method", "pbpc", "--output", doubtful], 0)
    result = yaml.safe_load(open(doubtful))
    if result["verdict"] != "doubtful" or sorted(result["views_to_check"]) != CORRUPTED:
        sys.exit("FAIL: corrupted session: verdict %s naming views %s (expected doubtful naming %s)"
                 % (result["verdict"], result.get("views_to_check"), CORRUPTED))

    ids = ",".join(str(i) for i in result["views_to_check"])
    kept = os.path.join(work, "kept.yaml")
    before = digest(bad)
    run([tool, "--quiet", "--load-session", bad, "--method", "pbpc", "--drop-views", ids,
         "--output", kept, "--save-session", os.path.join(work, "kept_session.yaml"), "--truth",
         truth, "--check-truth", "0.2", "0.01"], 0)
    result = yaml.safe_load(open(kept))
    note = "views 3, 7, 11, 15 left out by the user (--drop-views)"
    if result["verdict"] != "good" or result["views_used"] != 16 or note not in result["notes"]:
        sys.exit("FAIL: after --drop-views %s: verdict %s, %d views, notes %s"
                 % (ids, result["verdict"], result["views_used"], result["notes"]))
    kept_ids = [v["id"] for v in yaml.safe_load(open(os.path.join(work,
                                                                   "kept_session.yaml")))["views"]]
    if any(i in kept_ids for i in CORRUPTED) or len(kept_ids) != 16:
        sys.exit("FAIL: the saved session holds views %s" % kept_ids)

    for extra, why in ((["--drop-views", "3,99"], "no view 99 in the session (its views: 0-19)"),
                       (["--drop-views", ",".join(str(i) for i in range(20))],
                        "leaves no view to solve"),
                       (["--drop-views", "3", "--save-session", bad],
                        "would overwrite the loaded session"),
                       (["--drop-views", "3,,7"], "expects ids separated by commas"),
                       (["--drop-views", "-1"], "must be in [0, ")):
        out = run([tool, "--quiet", "--load-session", bad, "--method", "pbpc"] + extra, 2)
        if why not in out:
            sys.exit("FAIL: %s: expected '%s' in:\n%s" % (" ".join(extra), why, out))
    if digest(bad) != before:
        sys.exit("FAIL: the loaded session was changed")
    print("drop views: doubtful naming %s -> good on 16 views; usage errors named" % ids)


if __name__ == "__main__":
    main()
