#!/usr/bin/python3
"""The README commands test: every shell command shown in README.md and docs/**/*.md runs as
written on the built package.

Commands are extracted from the Markdown (fenced bash/sh blocks, untyped blocks whose lines
start with a known command, and inline code spans that start with one); each must have an
entry in CASES below, and every entry must still be in the docs, so a new command cannot be
added untested and a stale entry cannot linger. How an entry is checked:

  run       run it (placeholders such as /path/target.yaml or <name> replaced by real files)
            and require exit 0 and, optionally, a pattern in its output;
  live_*    a live session of several documented commands (roslaunch, rosbag play,
            rosservice call) against a private master, with checks on what they did;
  dev       developer commands of a personal build folder (`build/<you>`): the make targets
            exist in the build and every documented --flag is parsed by the tool's source
            (running the benchmarks takes minutes);
  rig_bringup  the one-line bring-up of a custom rig: a rig file my_rig.yaml with sensor names
            of its own in the work folder, the command as written, then every nodelet it must
            have loaded (detectors on the rig's topics, calibrator, projections) is checked;
  same_as   an inline form of a tested command (its text is a prefix of the tested one, after
            placeholders are replaced);
  runner    scripts/test.sh: the suite this test runs in.

Commands run the way a user runs them after `scripts/env.sh bash` (the built environment,
their own ROS_HOME, i.e. ~/.ros) from a folder that looks like the repository root (symlinks to
scripts/ and config/, the bundled recording as session.bag). HOME is a temporary folder, so
nothing lands in the real home directory.

Usage: check_readme_commands.py SOURCE_DIR BUILD_DIR [--only TEXT] [--list] [--keep]
Exit 0 pass, 1 fail, 77 skipped (../shared/data missing).
"""
import glob
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

COMMAND_WORDS = ("scripts/", "rosrun ", "roslaunch ", "rosservice ", "rostest ", "rosbag ", "rostopic ",
                 "make ", "cmake ", "export ", "build/", "ws/")

# Inline spans that are not runnable commands (paths, partial forms) with the reason.
NOT_COMMANDS = {
    "scripts/env.sh CMD ARGS…": "the env.sh synopsis; its README example is tested",
    "scripts/env.sh rosrun board_calib calibrate_bag": "names the tool in a benchmark record",
    "build/lead/devel/lib/board_calib/calibrate_bag": "names the binary a benchmark record used",
    "rosbag play --clock": "names the replay mode in a benchmark record",
    "scripts/env.sh": "names the script in prose",
    "roslaunch --nodes": "names how a launch file was checked in a benchmark record",
    "make all": "names a build step in a benchmark record",
    "rosbag reindex FILE": "advice for the user's own truncated bag (FILE)",
    "scripts/env.sh /usr/bin/python3 scripts/bench_cloud_memory.py --bag ../shared/data/basler_os1_plain/session.bag "
    "--topic /os1/points --target ../shared/data/basler_os1_plain/target.yaml --clouds 1000 --rate 2":
        "the memory benchmark's record: 1,000 clouds at 2 Hz take 8 minutes",
}

SHARED = None  # set in main: ../shared/data
# README's replay comment: the arguments it tells a user to add for a recorded bag.
REPLAY_ARGS = "use_sim_time:=true"

# command text (continuations joined, whitespace collapsed, trailing comment dropped) -> recipe
CASES = {
    # README
    "scripts/demo.sh": {"kind": "run", "expect": r"== 3\. result file", "timeout": 420},
    "scripts/test.sh": {"kind": "runner"},
    "scripts/build.sh": {"kind": "run", "expect": r"built in", "timeout": 600},
    "scripts/env.sh rosrun board_calib calibrate_bag --help": {"kind": "run", "expect": r"--bag"},
    "scripts/env.sh rosrun board_calib calibrate_bag --bag session.bag --target target.yaml --image-topic "
    "/camera/image_raw --camera-info-topic /camera/camera_info --cloud-topic /os1/points --method pbpc "
    "--output result.yaml --report report/": {
        "kind": "run", "timeout": 300,
        "expect": r"report written to report/",
        "files": ["result.yaml", "report/report.md", "report/edge_errors.png", "report/pose_coverage.png",
                  "report/overlay_view_0.jpg"]},
    # The report's session from the command above (order 0), two of its views left out.
    "scripts/env.sh rosrun board_calib calibrate_bag --load-session report/session.yaml --method pbpc "
    "--drop-views 3,7 --output result_kept.yaml": {
        "kind": "run", "timeout": 120, "order": 1, "expect": r"views 3, 7 left out \(--drop-views\)",
        "files": ["result_kept.yaml"]},
    "roslaunch board_calib calibration.launch target_file:=/path/target.yaml image:=/camera/image_raw "
    "camera_info:=/camera/camera_info points:=/os1/points rviz:=true": {"kind": "live_pair"},
    'rosservice call /calibrator/calibrate "{method: pbpc}"': {"kind": "live_pair"},
    "roslaunch board_calib publish_calibration.launch result_file:=~/.ros/board_calib/pbpc_result.yaml": {
        "kind": "live_pair"},
    "scripts/env.sh bash": {"kind": "run", "stdin": "rospack find board_calib\n", "expect_source_dir": True},
    "rostopic echo -n 1 /diagnostics": {"kind": "live_pair"},
    "rosrun tf tf_echo os1_lidar camera": {"kind": "live_pair"},
    "rosrun image_view image_view image:=/overlay": {"kind": "live_pair"},
    "roslaunch board_calib rig_calibration.launch rig_file:=my_rig.yaml": {"kind": "rig_bringup"},
    'rosservice call /calibrator/calibrate "{method: msg}"': {"kind": "live_rig"},
    "rosrun board_calib simulate_bag --scenario config/scenarios/<name>.yaml --out X.bag": {
        "kind": "run", "subs": [("<name>", "plain_vlp32c_1920")], "files": ["X.bag", "X.truth.yaml"],
        "timeout": 240},
    # docs/MSG.md
    "rosrun board_calib simulate_bag --scenario config/scenarios/multi_rig_apriltag.yaml --out /tmp/rig.bag": {
        "kind": "run", "files": ["tmp/rig.bag"], "timeout": 240, "order": 1},
    "rosrun board_calib calibrate_bag --config config/rigs/multi_rig_apriltag.yaml --bag /tmp/rig.bag --method msg "
    "--output /tmp/rig_result.yaml --report /tmp/rig_report [--truth /tmp/rig.truth.yaml [--check-truth 0.2 0.01]] "
    "[--quiet]": {"kind": "run", "files": ["tmp/rig_result.yaml", "tmp/rig_report/report.md"], "timeout": 300,
                  "order": 2},
    "roslaunch board_calib example_rig_calibration.launch use_sim_time:=true": {"kind": "live_rig"},
    "rosbag play --clock /tmp/rig.bag": {"kind": "live_rig"},
    'rosservice call /calibrator/save_session "{path: /tmp/rig_session.yaml}"': {"kind": "live_rig"},
    "roslaunch board_calib publish_calibration.launch result_file:=.../msg_rig_result.yaml": {"kind": "live_rig"},
    # docs/SIMULATOR.md
    "rosrun board_calib simulate_bag --scenario config/scenarios/plain_vlp32c_1920.yaml --out /tmp/sim.bag "
    "[--seed S] [--target-out T.yaml] [--truth-out G.yaml] [--start-time SEC] [--quiet]": {
        "kind": "run", "subs": [(" S]", " 3]"), ("SEC", "100")], "files": ["tmp/sim.bag", "T.yaml", "G.yaml"],
        "timeout": 240},
    # docs/BENCHMARKS.md, session 10's trust sweep
    "rosrun board_calib simulate_bag --scenario config/scenarios/plain_os1_noisy.yaml --out /tmp/os1.bag --seed 202": {
        "kind": "run", "files": ["tmp/os1.bag", "tmp/os1.truth.yaml"], "timeout": 240, "order": 1},
    "rosrun board_calib calibrate_bag --bag /tmp/os1.bag --target /tmp/os1.target.yaml --image-topic /camera/image_raw "
    "--camera-info-topic /camera/camera_info --cloud-topic /os1/points --method pbpc --output /tmp/os1_result.yaml "
    "--truth /tmp/os1.truth.yaml": {
        "kind": "run", "files": ["tmp/os1_result.yaml"], "timeout": 300, "order": 2,
        "expect": r"error vs truth \(pbpc\)"},
    # docs/nodes/projection.md
    "roslaunch board_calib projection.launch manager:=<manager> image:=... camera_info:=... points:=...": {
        "kind": "run", "launch_check_only": True},
    # docs/DEVELOPING.md
    "export PATH=/usr/bin:$PATH": {"kind": "run"},
    "cmake -S . -B build/<you> -DCMAKE_BUILD_TYPE=Release -DPYTHON_EXECUTABLE=/usr/bin/python3 "
    "-DCATKIN_ENABLE_TESTING=ON": {"kind": "dev"},
    "make -C build/<you> -j2 test_<yours>": {"kind": "dev", "yours": "test_report_plots"},
    "build/<you>/devel/lib/board_calib/test_<yours>": {"kind": "dev", "yours": "test_report_plots"},
    # docs/BENCHMARKS.md
    "make -C build/<you> -j2 bench_solvers": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_solvers --seeds 10 --trials 100": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_projection --iterations 50 --save build/<you>": {"kind": "dev"},
    "make -C build/<you> -j2 bench_msg_graph": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_msg_graph --scenes 10 --trials 100": {"kind": "dev"},
    "make -C build/<you> -j2 bench_lidar_detector test_lidar_detector test_lidar_detector_real": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_lidar_detector --data ../shared/data --repeat 5": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/test_lidar_detector": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/test_lidar_detector_real": {"kind": "dev"},
    "make -C build/<you> -j2 bench_sim": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_sim": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_sim --poses 30 config/scenarios/plain_vlp32c_1920.yaml": {"kind": "dev"},
    "build/<you>/devel/lib/board_calib/bench_image_detector --frames 20": {"kind": "dev"},
    "scripts/build.sh bench_lidar_detector test_lidar_detector test_lidar_detector_real": {
        "kind": "run", "expect": r"built in", "timeout": 900},
    "ws/ci/devel/lib/board_calib/bench_lidar_detector --repeat 3 [--no-sparse]": {"kind": "dev"},
    "scripts/build.sh bench_msg_graph": {"kind": "run", "expect": r"built in", "timeout": 900},
    "ws/ci/devel/lib/board_calib/bench_msg_graph --scenes 10 --trials 100": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_msg_graph --scenario test/data/msg_rig_checker_scenario.yaml --scenes 5": {
        "kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_lidar_detector --sim-table config/scenarios/plain_vlp16_outdoor_far.yaml": {
        "kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_lidar_detector --gtest_filter='*Scenario*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_far_sim": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_tracker": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_trace": {"kind": "dev"},
    "scripts/build.sh test_image_detector_augmented bench_image_detector": {
        "kind": "run", "expect": r"built in", "timeout": 900},
    "ws/ci/devel/lib/board_calib/test_image_detector_augmented --gtest_filter='*RealFrames'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector --gtest_filter='*FarBoardBehind*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_tracker --gtest_filter='ScenePrepass.*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_far_sim --gtest_filter='*Street*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_image_memory --hz 10 --seconds 60": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_image_memory --hz 30 --seconds 60": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_image_detector --frames 20 --board plain": {"kind": "dev"},
    "scripts/build.sh bench_image_detector test_image_detector_augmented test_image_far_sim test_line_segments": {
        "kind": "run", "expect": r"built in", "timeout": 900},
    "ws/ci/devel/lib/board_calib/bench_image_detector --frames 20 --board plain --stages": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_far_sim --gtest_filter='*StreetFrames*:*Plain*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_far_sim --gtest_filter='*StreetFrames*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_line_segments": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector --gtest_filter='*RoomsGrey*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector --gtest_filter='PlainEdges.*'": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector_augmented": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_image_detector_second_chance": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_image_detector": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_capture --scale 0.5 --poses 12 --seeds 2 --rates 1,2,5,10,30": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_rig_session --gtest_filter=*Sparse*": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --seeds 21,22,23,24": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --session --seeds 21,22,23,24": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --pairs-only --seeds 21,22,23,24": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --seeds 21,22,23,24 --hz 10 --images --session": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --seeds 21,22 --hz 10 --images": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_stillness --seeds 21,22 --hz 10 --images --pairs-only": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_stillness_far": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/test_rig_calibration": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_capture --scenario config/scenarios/checker_vlp16_1280.yaml --method ppc "
    "--poses 12 --seeds 2 --rates 1,2,5,10,30": {"kind": "dev"},
    "ws/ci/devel/lib/board_calib/bench_capture --scenario config/scenarios/checker_vlp16_1280.yaml --method ppc "
    "--poses 30 --seeds 2 --rates 1 --layouts organized": {"kind": "dev"},
    # docs/RELIABILITY.md
    "scripts/build.sh test_fuzz_inputs test_fuzz_rig test_fuzz_detectors && "
    "ws/ci/devel/lib/board_calib/test_fuzz_inputs": {"kind": "run", "expect": r"PASSED", "timeout": 900},
    "ws/ci/devel/lib/board_calib/test_fuzz_detectors": {"kind": "run", "expect": r"PASSED", "timeout": 600},
    "scripts/test.sh --sanitize": {"kind": "runner"},
}


# ------------------------------------------------------------------------------------------
# Extraction
# ------------------------------------------------------------------------------------------
def normalise(text):
    text = re.sub(r"\\\n\s*", " ", text)
    text = re.sub(r"(^|\s)#\s.*$", "", text)  # trailing comment
    return re.sub(r"\s+", " ", text).strip()


def extract(source_dir):
    """{command: [file, ...]} for every command shown in the docs."""
    found = {}
    files = [os.path.join(source_dir, "README.md")] + sorted(glob.glob(os.path.join(source_dir, "docs", "**", "*.md"),
                                                                       recursive=True))
    for path in files:
        rel = os.path.relpath(path, source_dir)
        text = open(path, encoding="utf-8").read()
        for lang, body in re.findall(r"```(\w*)\n(.*?)```", text, flags=re.S):
            if lang not in ("", "bash", "sh", "shell", "console"):
                continue
            body = re.sub(r"\\\n\s*", " ", body)
            for line in body.splitlines():
                command = normalise(line)
                if not command or command.startswith("#"):
                    continue
                if lang == "" and not command.startswith(COMMAND_WORDS):
                    continue  # YAML, BibTeX, ...
                found.setdefault(command, []).append(rel)
        prose = re.sub(r"```.*?```", "", text, flags=re.S)
        for span in re.findall(r"`([^`]+)`", prose):
            command = normalise(span)
            if command.startswith(COMMAND_WORDS) and (" " in command or command.startswith("scripts/")):
                found.setdefault(command, []).append(rel)
    return found


# ------------------------------------------------------------------------------------------
# Running
# ------------------------------------------------------------------------------------------
class Env:
    def __init__(self, source_dir, build_dir, work):
        self.source_dir, self.build_dir, self.work = source_dir, build_dir, work
        self.home = os.path.join(work, "home")
        os.makedirs(self.home, exist_ok=True)
        os.makedirs(os.path.join(work, "tmp"), exist_ok=True)
        for name in ("scripts", "config"):
            os.symlink(os.path.join(source_dir, name), os.path.join(work, name))
        # Commands written from the package root name the build as ws/ci.
        os.makedirs(os.path.join(work, "ws"), exist_ok=True)
        os.symlink(build_dir, os.path.join(work, "ws", "ci"))
        plain = os.path.join(SHARED, "basler_os1_plain")
        os.symlink(os.path.join(plain, "session.bag"), os.path.join(work, "session.bag"))
        os.symlink(os.path.join(plain, "target.yaml"), os.path.join(work, "target.yaml"))
        self.target = os.path.join(plain, "target.yaml")
        port = free_port()
        self.vars = dict(os.environ)
        for k in ("ROS_HOME", "ROS_LOG_DIR", "DISPLAY"):
            self.vars.pop(k, None)
        self.vars.update({"HOME": self.home, "BOARD_CALIB_BUILD": build_dir, "ROS_HOSTNAME": "localhost",
                          "ROS_MASTER_URI": "http://localhost:%d" % port, "PATH": "/usr/bin:/bin:" + os.environ["PATH"],
                          "LIBGL_ALWAYS_SOFTWARE": "1", "PYTHONUNBUFFERED": "1"})
        # What `scripts/env.sh bash` gives a user.
        self.prelude = "source %s/devel/setup.bash && export ROS_PACKAGE_PATH=%s:$ROS_PACKAGE_PATH && " % (
            shlex.quote(build_dir), shlex.quote(source_dir))

    def substitute(self, command, subs=()):
        for old, new in subs:
            command = command.replace(old, new)
        command = command.replace("/path/target.yaml", self.target).replace("/tmp/", self.work + "/tmp/")
        return command.replace("[", "").replace("]", "")

    def run(self, command, timeout, log, stdin=""):
        log.write("$ " + command + "\n")
        log.flush()
        try:
            p = subprocess.run(["bash", "-c", self.prelude + command], cwd=self.work, env=self.vars,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout,
                               universal_newlines=True, input=stdin, start_new_session=True)
        except subprocess.TimeoutExpired as e:
            log.write("(timed out after %d s)\n" % timeout)
            return 124, e.output.decode() if isinstance(e.output, bytes) else (e.output or "")
        log.write(p.stdout)
        return p.returncode, p.stdout

    def start(self, command, log_path, xvfb=False, line_buffered=False):
        # stdbuf: a C++ tool writing to a file buffers its output until it exits.
        wrapped = self.prelude + ("exec xvfb-run -a -s '-screen 0 1400x900x24' " if xvfb else "exec ") + (
            "stdbuf -oL " if line_buffered else "") + command
        return subprocess.Popen(["bash", "-c", wrapped], cwd=self.work, env=self.vars, stdout=open(log_path, "w"),
                                stderr=subprocess.STDOUT, start_new_session=True)


def free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def stop(proc, grace=15):
    if proc.poll() is not None:
        return
    os.killpg(proc.pid, signal.SIGINT)
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def wait_until(env, check_command, timeout, log):
    end = time.time() + timeout
    while time.time() < end:
        rc, out = env.run(check_command, 30, log)
        if rc == 0:
            return out
        time.sleep(1)
    return None


def launch_args_declared(env, command):
    """Every name:=value of a roslaunch command is an <arg> of the launch file (roslaunch
    silently ignores unknown ones)."""
    words = shlex.split(command)
    i = words.index("roslaunch") + 1
    while words[i].startswith("-"):
        i += 1
    package, launch = words[i], words[i + 1]
    path = os.path.join(env.source_dir, "launch", launch) if package == "board_calib" else None
    if not path or not os.path.exists(path):
        return "launch file %s/%s not found" % (package, launch)
    declared = {a.get("name") for a in ET.parse(path).getroot().findall("arg")}
    unknown = [w.split(":=")[0] for w in words[i + 2:] if ":=" in w and w.split(":=")[0] not in declared]
    return "undeclared launch arguments %s in %s" % (unknown, launch) if unknown else ""


def check_run(env, command, case, log):
    cmd = env.substitute(command, case.get("subs", ()))
    if case.get("launch_check_only"):
        cmd = cmd.replace("...", "/x").replace("<manager>", "board_calib_manager")
        why = launch_args_declared(env, cmd)
        if why:
            return why
        rc, out = env.run(cmd.replace("roslaunch ", "roslaunch --nodes ", 1), 60, log)
        return "" if rc == 0 else "roslaunch --nodes failed (exit %d)" % rc
    if command.startswith("roslaunch"):
        why = launch_args_declared(env, cmd)
        if why:
            return why
    rc, out = env.run(cmd, case.get("timeout", 120), log, case.get("stdin", ""))
    if rc != 0:
        return "exit %d" % rc
    if case.get("expect_source_dir") and env.source_dir not in out:
        return "the shell does not see the package at %s" % env.source_dir
    if "expect" in case and not re.search(case["expect"], out):
        return "output lacks /%s/" % case["expect"]
    for f in case.get("files", []):
        if not os.path.exists(os.path.join(env.work, f)):
            return "did not write %s" % f
    return ""


def check_dev(env, command, case, log):
    """make targets exist in the build; documented flags are parsed by the tool; the test
    binary named for `test_<yours>` runs."""
    cmd = command.replace("test_<yours>", case.get("yours", "test_<yours>"))
    if cmd.startswith("export "):
        return ""
    if cmd.startswith("cmake "):
        # Re-configuring the suite's own build folder is what the line does for build/<you>.
        rc, _ = env.run(cmd.replace("build/<you>", env.build_dir).replace("-S .", "-S " + env.source_dir), 180, log)
        return "" if rc == 0 else "cmake exit %d" % rc
    if cmd.startswith("make "):
        targets = [w for w in shlex.split(cmd)[4:] if not w.startswith("-")]
        rc, out = env.run("make -C %s -q %s; test $? -ne 2" % (env.build_dir, " ".join(targets)), 120, log)
        return "" if rc == 0 else "make does not know %s" % targets
    words = shlex.split(cmd)
    tool = os.path.basename(words[0])
    binary = os.path.join(env.build_dir, "devel", "lib", "board_calib", tool)
    if not os.access(binary, os.X_OK):
        return "%s is not built" % binary
    if tool.startswith("test_") and tool == case.get("yours"):
        rc, _ = env.run(binary, 120, log)
        return "" if rc == 0 else "%s exit %d" % (tool, rc)
    source = os.path.join(env.source_dir, "src", "tools", tool + ".cpp")
    if tool.startswith("test_"):
        return ""  # a gtest binary of the suite: built above, run by ctest itself
    text = open(source).read()
    missing = [w for w in words[1:] if w.startswith("--") and '"%s"' % w not in text]
    return "%s does not parse %s" % (tool, missing) if missing else ""


def check_live_pair(env, log):
    """README live: bring-up with the documented arguments (rviz under Xvfb) plus the replay
    arguments of README's comment, the documented replay, the README's watching commands while
    it plays, the documented service call, then publish_calibration on the result file."""
    problems = []
    launch = env.substitute("roslaunch board_calib calibration.launch target_file:=/path/target.yaml "
                            "image:=/camera/image_raw camera_info:=/camera/camera_info points:=/os1/points rviz:=true "
                            + REPLAY_ARGS)
    why = launch_args_declared(env, launch)
    if why:
        return why
    proc = env.start(launch, os.path.join(env.work, "live_pair_launch.log"), xvfb=True)
    try:
        if wait_until(env, "rosservice list | grep -q /calibrator/calibrate", 90, log) is None:
            return "calibrator services never came up (see live_pair_launch.log)"
        # rviz's "LiDAR points" display must listen to the remapped cloud topic.
        if wait_until(env, "rostopic info /os1/points | grep -q '/rviz'", 60, log) is None:
            problems.append("rviz does not subscribe to /os1/points")
        # Watching a session (README) while the bag plays (with sim time, nothing is published
        # once the clock stops): diagnostics and the overlay in image_view.
        diag_log = os.path.join(env.work, "diagnostics_echo.log")
        diag = env.start("rostopic echo -n 1 /diagnostics", diag_log)
        player = env.start("rosbag play --clock session.bag", os.path.join(env.work, "rosbag_play.log"))
        viewer = env.start("rosrun image_view image_view image:=/overlay", os.path.join(env.work, "image_view.log"),
                           xvfb=True)
        if wait_until(env, "rostopic info /overlay | grep -q image_view", 60, log) is None:
            problems.append("image_view did not subscribe to /overlay")
        stop(viewer)
        player.wait(300)
        if player.returncode != 0:
            problems.append("rosbag play exit %d" % player.returncode)
        try:
            diag.wait(10)
        except subprocess.TimeoutExpired:
            stop(diag)
        if diag.returncode != 0 or "level:" not in open(diag_log).read():
            problems.append("rostopic echo -n 1 /diagnostics received nothing while the bag played (exit %s)" %
                            diag.returncode)
        rc, out = env.run('rosservice call /calibrator/calibrate "{method: pbpc}"', 180, log)
        if rc != 0 or "success:" not in out:
            return "; ".join(problems + ["rosservice call exit %d" % rc])
        views = re.search(r"views_used: (\d+)", out)
        print("live pair: %s, %s views" % ("calibrated" if "success: True" in out else "FAILED",
                                           views.group(1) if views else "?"))
        if "success: True" not in out:
            problems.append("the live calibration of the bundled recording failed: %s" %
                            " ".join(l.strip() for l in out.splitlines() if "message" in l or "reason" in l)[:300])
        else:
            # The replay is over and its clock stopped: back to wall time, as a live session runs,
            # so tf_echo's loop turns (the result is on the latched /tf_static).
            env.run("rosparam set /use_sim_time false", 30, log)
            echo_log = os.path.join(env.work, "tf_echo.log")
            echo = env.start("rosrun tf tf_echo os1_lidar camera", echo_log, line_buffered=True)
            end = time.time() + 90
            while time.time() < end and "Translation" not in open(echo_log).read():
                time.sleep(1)
            stop(echo)
            if "Translation" not in open(echo_log).read():
                problems.append("rosrun tf tf_echo os1_lidar camera printed no transform")
    finally:
        stop(proc)
    result = os.path.join(env.home, ".ros", "board_calib", "pbpc_result.yaml")
    if not os.path.exists(result):
        problems.append("no %s (README: results land in ~/.ros/board_calib)" % result)
        return "; ".join(problems)
    pub = env.start("roslaunch board_calib publish_calibration.launch result_file:=~/.ros/board_calib/pbpc_result.yaml",
                    os.path.join(env.work, "publish_pair.log"))
    try:
        if wait_until(env, "timeout 20 rostopic echo -n 1 /tf_static | grep -q os1_lidar", 60, log) is None:
            problems.append("publish_calibration did not broadcast os1_lidar -> camera")
    finally:
        stop(pub)
    return "; ".join(problems)


# A rig whose names appear nowhere in the package; its target relative to the rig file (the work
# folder, where config/ is linked), as a user writes it next to their own board file.
MY_RIG = """target: config/targets/apriltag_grid_4x4.yaml
reference: roof_lidar
cameras:
  - {name: front_cam, image_topic: /front_cam/image_raw, camera_info_topic: /front_cam/camera_info}
lidars:
  - {name: roof_lidar, cloud_topic: /roof_lidar/points}
  - {name: bumper_lidar, cloud_topic: /bumper_lidar/points}
"""


def check_rig_bringup(env, command, log):
    """The one-liner from a relative rig file: every nodelet of the rig comes up, subscribed to
    the rig file's topics (seen in the master's graph)."""
    with open(os.path.join(env.work, "my_rig.yaml"), "w") as f:
        f.write(MY_RIG)
    why = launch_args_declared(env, command)
    if why:
        return why
    proc = env.start(command, os.path.join(env.work, "rig_bringup_launch.log"))
    try:
        if wait_until(env, "rosservice list | grep -q /calibrator/calibrate", 90, log) is None:
            return "the rig calibrator never came up (see rig_bringup_launch.log)"
        want = ["/front_cam/camera_board", "/roof_lidar/lidar_board", "/bumper_lidar/lidar_board",
                "/front_cam_roof_lidar/overlay", "/front_cam_bumper_lidar/overlay"]
        missing = []
        for topic in want:
            if wait_until(env, "rostopic list | grep -qx " + topic, 30, log) is None:
                missing.append(topic)
        # The detectors' inputs are the rig file's topics: the calibrator subscribes to the
        # features, which wakes the lazy detectors onto them.
        for topic in ["/front_cam/image_raw", "/roof_lidar/points", "/bumper_lidar/points"]:
            if wait_until(env, "rostopic info %s | sed -n '/Subscribers:/,$p' | grep -q board_calib_manager" % topic,
                          30, log) is None:
                missing.append(topic + " (no subscriber)")
        return "missing: " + ", ".join(missing) if missing else ""
    finally:
        stop(proc)


def check_live_rig(env, log):
    """docs/MSG.md live: rig bring-up with sim time, replay of the simulated rig bag, calibrate
    and save_session, then publish_calibration on msg_rig_result.yaml."""
    bag = os.path.join(env.work, "tmp", "rig.bag")
    if not os.path.exists(bag):
        return "no %s (the MSG.md simulate_bag line runs first)" % bag
    problems = []
    proc = env.start("roslaunch board_calib example_rig_calibration.launch use_sim_time:=true",
                     os.path.join(env.work, "live_rig_launch.log"))
    try:
        if wait_until(env, "rosservice list | grep -q /calibrator/calibrate", 90, log) is None:
            return "rig calibrator services never came up (see live_rig_launch.log)"
        rc, _ = env.run(env.substitute("rosbag play --clock /tmp/rig.bag"), 300, log)
        if rc != 0:
            problems.append("rosbag play exit %d" % rc)
        rc, out = env.run('rosservice call /calibrator/calibrate "{method: msg}"', 240, log)
        if rc != 0 or "success: True" not in out:
            problems.append("rig calibrate did not succeed (exit %d)" % rc)
        rc, out = env.run(env.substitute('rosservice call /calibrator/save_session "{path: /tmp/rig_session.yaml}"'),
                          60, log)
        if rc != 0 or not os.path.exists(os.path.join(env.work, "tmp", "rig_session.yaml")):
            problems.append("save_session did not write the file")
    finally:
        stop(proc)
    result = os.path.join(env.home, ".ros", "board_calib", "msg_rig_result.yaml")
    if not os.path.exists(result):
        return "; ".join(problems + ["no %s" % result])
    pub = env.start("roslaunch board_calib publish_calibration.launch result_file:=" + result,
                    os.path.join(env.work, "publish_rig.log"))
    try:
        if wait_until(env, "timeout 20 rostopic echo -n 1 /tf_static | grep -q child_frame_id", 60, log) is None:
            problems.append("publish_calibration did not broadcast the rig")
    finally:
        stop(pub)
    return "; ".join(problems)


def main():
    global SHARED
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    only = sys.argv[sys.argv.index("--only") + 1] if "--only" in sys.argv else None
    if only in args:
        args.remove(only)
    source_dir, build_dir = os.path.realpath(args[0]), os.path.realpath(args[1])
    found = extract(source_dir)
    if "--list" in sys.argv:
        for c, where in found.items():
            kind = CASES.get(c, {}).get("kind", "not a command" if c in NOT_COMMANDS else "UNTESTED")
            print("%-14s %s   [%s]" % (kind, c, ", ".join(where)))
        return 0

    failures = []
    for command, where in found.items():
        if command not in CASES and command not in NOT_COMMANDS:
            failures.append("untested command (add it to CASES in %s): %s   [%s]" % (__file__, command, ", ".join(where)))
    for command in CASES:
        if command not in found:
            failures.append("stale entry (no longer in the docs): " + command)
    for command, case in CASES.items():
        if case["kind"] == "same_as" and not (case["of"].startswith(command) and case["of"] in CASES):
            failures.append("same_as entry is not a prefix of a tested command: " + command)
    readme = open(os.path.join(source_dir, "README.md"), encoding="utf-8").read()
    for arg in REPLAY_ARGS.split():
        if "add " + arg not in readme and "and " + arg not in readme and "(and " + arg not in readme:
            failures.append("README's replay comment no longer mentions %s (REPLAY_ARGS)" % arg)
    if failures:
        print("\n".join("FAIL: " + f for f in failures))
        return 1

    SHARED = os.path.realpath(os.path.join(source_dir, "..", "shared", "data"))
    if not os.path.isdir(SHARED):
        print("SKIP: ../shared/data is missing")
        return 77
    work = tempfile.mkdtemp(prefix="readme_commands_", dir=os.path.join(build_dir))
    env = Env(source_dir, build_dir, work)
    log = open(os.path.join(work, "commands.log"), "w")
    print("work folder and logs: " + work)

    def selected(c):
        return only is None or only in c

    results = []
    # The rig session replays the bag the MSG.md simulate_bag line (order 1) writes.
    ordered = sorted(CASES.items(), key=lambda kv: kv[1].get("order", 3 if kv[1]["kind"] == "live_rig" else 0))
    live_done = {}
    for command, case in ordered:
        if not selected(command):
            continue
        kind = case["kind"]
        start = time.time()
        if kind == "runner":
            results.append((command, "covered", "this test runs inside it", 0.0))
            continue
        if kind == "same_as":
            results.append((command, "covered", "prefix of: " + case["of"], 0.0))
            continue
        if kind in ("live_pair", "live_rig"):
            if kind not in live_done:
                live_done[kind] = (check_live_pair if kind == "live_pair" else check_live_rig)(env, log)
                why = live_done[kind]
                results.append(("[%s session]" % kind, "FAIL" if why else "ok", why, time.time() - start))
            results.append((command, "covered", "in the %s session above" % kind, 0.0))
            continue
        try:
            if kind == "rig_bringup":
                why = check_rig_bringup(env, command, log)
            else:
                why = check_dev(env, command, case, log) if kind == "dev" else check_run(env, command, case, log)
        except subprocess.TimeoutExpired:
            why = "timed out"
        results.append((command, "FAIL" if why else "ok", why, time.time() - start))
    failed = 0
    for command, status, why, seconds in results:
        failed += status == "FAIL"
        print("%-7s %5.0f s  %s%s" % (status, seconds, command, ("\n                 -> " + why) if why else ""))
    print("%d commands, %d failed; logs in %s" % (len(results), failed, work))
    if failed == 0 and "--keep" not in sys.argv:
        subprocess.run(["rm", "-rf", work])
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
