#!/usr/bin/python3
"""Runs calibrate_bag on a real recording of ../shared/data and checks the outcome.

plain:   --method pbpc on basler_os1_plain; the independent tool ../shared/tools/mlre must score
         the result better than the authors' own published extrinsic (6.09 px), and the run must
         flag the board-size inconsistency the data README describes.
checker: --method all on left_vlp32_checker; PPC must succeed with its plane RMS and 1 sigma in
         the result file, and the three methods must be printed side by side.
"""
import argparse
import os
import re
import subprocess
import sys

import yaml

AUTHORS_MLRE_PX = 6.09  # ../shared/tools/mlre/README.md


def run(cmd):
    print('$', ' '.join(cmd), flush=True)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    print(proc.stdout, flush=True)
    return proc


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('case', choices=['plain', 'checker'])
    ap.add_argument('--tool', required=True, help='calibrate_bag executable')
    ap.add_argument('--shared', required=True, help='the ../shared folder')
    ap.add_argument('--out', required=True, help='output folder')
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    data = os.path.join(args.shared, 'data')
    failures = []

    if args.case == 'plain':
        folder = os.path.join(data, 'basler_os1_plain')
        result = os.path.join(args.out, 'plain_pbpc.yaml')
        report = os.path.join(args.out, 'plain_report')
        proc = run([args.tool, '--bag', os.path.join(folder, 'session.bag'), '--target', os.path.join(folder, 'target.yaml'),
                    '--image-topic', '/camera/image_raw', '--camera-info-topic', '/camera/camera_info',
                    '--cloud-topic', '/os1/points', '--method', 'pbpc', '--output', result, '--report', report])
        if proc.returncode != 0:
            print('calibrate_bag failed')
            return 1
        mlre_dir = os.path.join(args.shared, 'tools', 'mlre')
        score = run(['/usr/bin/python3', os.path.join(mlre_dir, 'mlre.py'), '--ref', os.path.join(mlre_dir, 'ref_basler_os1_plain'),
                     '--extrinsic', result])
        match = re.search(r'MLRE mean ([0-9.]+) px', score.stdout)
        if score.returncode != 0 or not match:
            failures.append('the mlre tool could not score the result')
        else:
            mlre = float(match.group(1))
            print(f'independent MLRE {mlre:.3f} px (authors\' extrinsic {AUTHORS_MLRE_PX} px)')
            if not mlre < AUTHORS_MLRE_PX:
                failures.append(f'MLRE {mlre:.3f} px is not better than the authors\' {AUTHORS_MLRE_PX} px')
        with open(result) as f:
            notes = yaml.safe_load(f).get('notes', [])
        if not any('board size inconsistency' in n for n in notes):
            failures.append('the result does not flag the board-size inconsistency')
        with open(os.path.join(report, 'report.md')) as f:
            if 'board size inconsistency' not in f.read():
                failures.append('the report does not flag the board-size inconsistency')
    else:
        folder = os.path.join(data, 'left_vlp32_checker')
        result = os.path.join(args.out, 'checker_all.yaml')
        proc = run([args.tool, '--bag', os.path.join(folder, 'session.bag'), '--target', os.path.join(folder, 'target.yaml'),
                    '--image-topic', '/camera/image_raw', '--camera-info-topic', '/camera/camera_info',
                    '--cloud-topic', '/lidar/points', '--method', 'all', '--output', result])
        if proc.returncode != 0:
            print('calibrate_bag failed')
            return 1
        for method in ('ppc', 'pbpc', 'msg'):
            if not re.search(r'^\| ' + method + r' \| yes \|', proc.stdout, re.M):
                failures.append(f'{method} missing or failed in the side-by-side table')
        ppc = run([args.tool, '--bag', os.path.join(folder, 'session.bag'), '--target', os.path.join(folder, 'target.yaml'),
                   '--image-topic', '/camera/image_raw', '--camera-info-topic', '/camera/camera_info',
                   '--cloud-topic', '/lidar/points', '--method', 'ppc', '--output', os.path.join(args.out, 'checker_ppc.yaml'),
                   '--quiet'])
        if ppc.returncode != 0:
            failures.append('--method ppc failed')
        else:
            with open(os.path.join(args.out, 'checker_ppc.yaml')) as f:
                r = yaml.safe_load(f)
            if r.get('method') != 'ppc':
                failures.append('result method is not ppc')
            rms = r.get('quality', {}).get('plane_rms_mm')
            sd = r.get('stddev', {})
            if rms is None or not (0 < rms < 50):
                failures.append(f'plane RMS missing or implausible: {rms}')
            if len(sd.get('translation_m', [])) != 3 or len(sd.get('rotation_deg', [])) != 3:
                failures.append('1 sigma missing from the result')
            if r.get('views_used', 0) < 20:
                failures.append(f"only {r.get('views_used')} views used of 32 captures")
    for f in failures:
        print('FAIL:', f)
    print('OK' if not failures else f'{len(failures)} check(s) failed')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(main())
