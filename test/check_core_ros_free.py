#!/usr/bin/python3
"""Fails if any core header or source includes a ROS header (the core must stay ROS-free)."""
import pathlib
import re
import sys

ROS_INCLUDE = re.compile(
    r'^\s*#\s*include\s*[<"]('
    r'ros/|nodelet/|pluginlib/|tf2_ros/|tf2_eigen/|tf2_msgs/|tf/|pcl_ros/|pcl_conversions/|cv_bridge/|'
    r'image_transport/|image_geometry/|dynamic_reconfigure/|diagnostic_updater/|rosbag/|message_filters/|'
    r'[a-z0-9_]+_msgs/|board_calib/(?!core/)'
    r')')


def main():
    root = pathlib.Path(sys.argv[1])
    files = sorted(list((root / 'include/board_calib/core').rglob('*.h')) + list((root / 'src/core').rglob('*.cpp')))
    if not files:
        print('no core files found under', root)
        return 1
    bad = []
    for path in files:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if ROS_INCLUDE.match(line):
                bad.append(f'{path.relative_to(root)}:{number}: {line.strip()}')
    if bad:
        print('ROS headers included from the ROS-free core:')
        print('\n'.join(bad))
        return 1
    print(f'{len(files)} core files checked: no ROS includes')
    return 0


if __name__ == '__main__':
    sys.exit(main())
