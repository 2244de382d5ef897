#!/usr/bin/python3
"""calibrate_bag refuses a bad option before it reads anything: exit 2, the option named.

usage: check_cli_usage.py CALIBRATE_BAG
Each limit is the one the core checks later (SessionOptions, SolverOptions), so a value the
command line accepts is never refused after minutes of reading a bag. No bag is needed: every
case stops while the command line is parsed (the bag named does not exist).
"""
import subprocess
import sys

BASE = ["--bag", "/nonexistent.bag", "--target", "/nonexistent.yaml", "--image-topic", "/i",
        "--camera-info-topic", "/c", "--cloud-topic", "/p", "--method", "pbpc"]

REFUSED = [
    (["--sync-tolerance", "5"], "--sync-tolerance must be in (0, 1]"),
    (["--sync-tolerance", "0"], "--sync-tolerance must be in (0, 1]"),
    (["--sync-tolerance", "nan"], "--sync-tolerance expects a finite number"),
    (["--edge-shift", "2.5"], "--edge-shift must be in [-2, 2]"),
    (["--edge-shift", "-3"], "--edge-shift must be in [-2, 2]"),
    (["--still-frames", "2.5"], "--still-frames expects a whole number"),
    (["--loss-scale", "0"], "--loss-scale must be in (0, 10]"),
    (["--drop-views", "a"], "--drop-views expects a number"),
    (["--initial-guess", "0", "0", "0", "0", "0", "0", "0"], "has norm 0, not 1"),
    (["--capture", "sometimes"], "--capture must be all or still"),
    (["--bogus"], "unknown option '--bogus'"),
]
# Accepted by the command line: the run then stops at the missing target file (exit 1).
ACCEPTED = [["--sync-tolerance", "1"], ["--edge-shift", "-2"], ["--edge-shift", "2"]]


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    tool = sys.argv[1]
    for extra, why in REFUSED:
        p = subprocess.run([tool] + BASE + extra, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
        if p.returncode != 2 or why not in p.stderr:
            sys.exit("FAIL: %s: exit %d, expected 2 with '%s'\n%s" % (" ".join(extra), p.returncode,
                                                                     why, p.stderr))
    for extra in ACCEPTED:
        p = subprocess.run([tool] + BASE + extra, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                           text=True)
        if p.returncode == 2:
            sys.exit("FAIL: %s refused: %s" % (" ".join(extra), p.stderr))
    print("%d bad options refused with their reason, %d limits accepted" % (len(REFUSED),
                                                                           len(ACCEPTED)))


if __name__ == "__main__":
    main()
