# Copyright 2026 The pseudo_stereo_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
``pseudo_stereo calibrate``: write a camera's calibration YAML from chessboards or points.

Modes: ``intrinsics`` (chessboard images, or every n-th frame of a video
file or camera that shows the board), ``extrinsics`` (pose from a
correspondence CSV and known intrinsics, from this package's files or a plain
camera_info YAML such as ROS camera_calibration's ``ost.yaml``) and ``full``
(everything from a correspondence CSV).  A correspondence CSV has the header ``x,y,z,u,v``:
world metres and raw pixels, one point per line.  Every mode prints the RMS
and the residual of each point, flags outliers and draws a PNG of the points
and their reprojections.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import re

import numpy as np

from . import UsageError
from ..calibrate import (auto_dist_terms, calibrate_extrinsics, calibrate_full,
                         calibrate_intrinsics, CalibrationResult, DISTORTION_TERMS,
                         list_images, video_boards)
from ..calibration import load_camera_info, PathLike, save_calibration
from ..formats.csv_io import CsvError, parse_float, read_rows

__all__ = ['NAME', 'HELP', 'add_arguments', 'read_correspondences', 'run', 'plot_result']

NAME = 'calibrate'
HELP = ('calibrate a camera: chessboard intrinsics, pose from known points, or a full '
        '(DLT + OpenCV) calibration; writes the calibration YAML')

CORRESPONDENCE_COLUMNS = ('x', 'y', 'z', 'u', 'v')
_SIZE = re.compile(r'^\s*(\d+)\s*[xX]\s*(\d+)\s*$')


def add_arguments(parser) -> None:
    """Add this command's modes and options."""
    modes = parser.add_subparsers(dest='mode', metavar='MODE', required=True)

    intrinsics = modes.add_parser(
        'intrinsics', help='camera matrix and distortion from chessboard images or a video',
        description='Camera matrix and distortion from chessboard images, or from every n-th '
                    'frame of a video file or camera that shows the board (OpenCV); the pose '
                    'in the written file is the identity: run `extrinsics` next.')
    frames = intrinsics.add_mutually_exclusive_group(required=True)
    frames.add_argument('--images', metavar='DIR',
                        help='directory of chessboard images (png, jpg, bmp, tif, pgm)')
    frames.add_argument('--video', metavar='FILE|DEVICE',
                        help='a video file, or a camera (/dev/videoN or an index)')
    intrinsics.add_argument('--every', type=int, default=10, metavar='N',
                            help='--video: look at every n-th frame (default 10)')
    intrinsics.add_argument('--frames', type=int, default=0, metavar='N',
                            help='--video: read at most N frames (0: the whole file; needed '
                                 'for a camera, e.g. 600 = 20 s at 30 fps)')
    intrinsics.add_argument('--max-boards', type=int, default=40, metavar='N',
                            help='--video: use at most N boards, spread over the video '
                                 '(default 40)')
    intrinsics.add_argument('--board', required=True, metavar='COLSxROWS',
                            help='inner corners per row x per column (9x7 squares -> 8x6)')
    intrinsics.add_argument('--square', required=True, metavar='M',
                            help='side of one square [m]')
    intrinsics.add_argument('--dist-terms', type=int, choices=DISTORTION_TERMS, default=4,
                            help='distortion terms to fit: 0, 1 (k1), 2 (k1 k2), 4 (+ p1 p2, '
                                 'default), 5 (+ k3)')
    intrinsics.add_argument('--min-boards', type=int, default=5, metavar='N',
                            help='refuse with fewer boards found (default 5)')
    _add_output_arguments(intrinsics)

    extrinsics = modes.add_parser(
        'extrinsics', help='camera pose from >= 4 world<->pixel points and known intrinsics',
        description='Camera pose (x_cam = R x_world + t) from at least 4 correspondences '
                    '(a plane is fine) and a calibration file giving the intrinsics.')
    extrinsics.add_argument('--intrinsics', required=True, metavar='CAMERA_INFO.yaml',
                            help='calibration YAML with the camera matrix and distortion: a '
                                 'file of this package or a camera_info YAML (ROS '
                                 'camera_calibration ost.yaml; rectification and projection '
                                 'matrices are ignored)')
    extrinsics.add_argument('--points', required=True, metavar='CORR.csv',
                            help='correspondences, header x,y,z,u,v (metres, raw pixels)')
    _add_output_arguments(extrinsics)

    full = modes.add_parser(
        'full', help='intrinsics, distortion and pose from >= 6 non-coplanar points',
        description='Intrinsics, distortion and pose from at least 6 non-coplanar '
                    'correspondences: a linear DLT start refined by OpenCV.')
    full.add_argument('--points', required=True, metavar='CORR.csv',
                      help='correspondences, header x,y,z,u,v (metres, raw pixels)')
    full.add_argument('--image-size', required=True, metavar='WxH', help='image size [px]')
    full.add_argument('--dist-terms', type=int, choices=DISTORTION_TERMS, default=None,
                      help='distortion terms to fit (default: by point count, 0 below 12 '
                           'points, k1 k2 below 40, all five from 40)')
    _add_output_arguments(full)


def _add_output_arguments(parser) -> None:
    parser.add_argument('--out', required=True, metavar='CAMERA.yaml',
                        help='the calibration YAML to write')
    parser.add_argument('--name', default=None,
                        help='camera_name in the file (default: the --out file stem, or the '
                             'name in the intrinsics file)')
    parser.add_argument('--plot', default=None, metavar='PATH',
                        help='residual plot PNG (default: next to --out, <stem>_residuals.png)')


def parse_size(text: str, option: str) -> tuple[int, int]:
    """Parse ``AxB`` (two positive integers) or raise :class:`UsageError` naming the option."""
    match = _SIZE.match(text or '')
    if not match or int(match.group(1)) <= 0 or int(match.group(2)) <= 0:
        raise UsageError(f'{option} {text!r}: expected two positive integers like 640x480')
    return int(match.group(1)), int(match.group(2))


def read_correspondences(path: PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    Read a correspondence CSV with the header ``x,y,z,u,v`` (extra columns are ignored).

    Read by :func:`~pseudo_stereo_ros.formats.csv_io.read_rows`, the reader of
    ``track``; lines starting with ``#`` are comments, the header is case-insensitive.

    :param path: the file
    :return: world points (N, 3) [m], raw pixels (N, 2) and the (N,) line number of each row
    :raises CsvError: naming the file, the line and the reason
    """
    rows, lines = [], []
    for source, line, row in read_rows(path, CORRESPONDENCE_COLUMNS, comments=True,
                                       lowercase=True):
        rows.append([parse_float(row[column], source, line, column)
                     for column in CORRESPONDENCE_COLUMNS])
        lines.append(line)
    if not rows:
        raise CsvError(f'{os.fspath(path)}: no points after the header')
    data = np.array(rows, dtype=float)
    return data[:, :3], data[:, 3:], np.array(lines)


def _check_output(text: str, option: str) -> Path:
    path = Path(text)
    if not path.parent.is_dir():
        raise UsageError(f'{option} {path}: directory {path.parent} does not exist')
    return path


def run(args) -> int:
    """Run the command."""
    out = _check_output(args.out, '--out')
    plot = _check_output(args.plot, '--plot') if args.plot else out.with_name(
        f'{out.stem}_residuals.png')
    lines = None
    if args.mode == 'intrinsics':
        board = parse_size(args.board, '--board')
        try:
            square = float(args.square)
        except ValueError:
            square = math.nan
        if not (math.isfinite(square) and square > 0):
            raise UsageError(f'--square {args.square!r}: expected a positive length [m]')
        labels = None
        if args.video is not None:
            images, labels, count = video_boards(
                args.video, board=board, every_n=args.every, max_frames=args.frames,
                max_boards=args.max_boards)
            print(f'{args.video}: {count} frames read; using {len(images)} of every '
                  f'{args.every}th that show the {board[0]}x{board[1]} board')
        else:
            images = list_images(args.images)
        result = calibrate_intrinsics(
            images, board=board, square_m=square, camera_name=args.name or out.stem,
            dist_terms=args.dist_terms, min_boards=args.min_boards, labels=labels)
    elif args.mode == 'extrinsics':
        intrinsics = load_camera_info(args.intrinsics)
        world, pixels, lines = read_correspondences(args.points)
        result = calibrate_extrinsics(intrinsics, world, pixels, camera_name=args.name,
                                      lines=lines)
    else:
        size = parse_size(args.image_size, '--image-size')
        world, pixels, lines = read_correspondences(args.points)
        terms = args.dist_terms if args.dist_terms is not None else auto_dist_terms(
            len(world))
        result = calibrate_full(world, pixels, size, camera_name=args.name or out.stem,
                                dist_terms=terms, lines=lines)
    # Write before the long residual table, so a closed pipe (`| head`) cannot lose the file.
    save_calibration(result.calibration, out)
    plot_result(result, plot, lines=lines)
    print(result.summary())
    print(f'wrote {out} and {plot}')
    print(_residual_table(result, lines))
    return 0


def _residual_table(result: CalibrationResult, lines: np.ndarray | None) -> str:
    flag = {True: '  OUTLIER', False: ''}
    if result.mode == 'intrinsics':
        # calibrate_intrinsics sets both; the other modes set world instead.
        assert result.image_rms_px is not None and result.point_image is not None
        rows = ['image  rms_px  max_px  outliers  file']
        for index, label in enumerate(result.image_labels):
            mine = result.point_image == index
            rows.append(f'{index:5d}  {result.image_rms_px[index]:6.3f}  '
                        f'{result.residuals_px[mine].max():6.3f}  '
                        f'{int(result.outliers[mine].sum()):8d}  {os.path.basename(label)}')
        return '\n'.join(rows)
    rows = ['line        x        y        z         u         v  residual_px']
    assert result.world is not None
    for i, (point, pixel, residual) in enumerate(zip(result.world, result.pixels,
                                                     result.residuals_px)):
        line = int(lines[i]) if lines is not None else i
        rows.append(f'{line:4d} {point[0]:8.4f} {point[1]:8.4f} {point[2]:8.4f} '
                    f'{pixel[0]:9.2f} {pixel[1]:9.2f} {residual:12.3f}'
                    f'{flag[bool(result.outliers[i])]}')
    return '\n'.join(rows)


def plot_result(result: CalibrationResult, path: PathLike, *,
                lines: np.ndarray | None = None) -> None:
    """
    Draw the measured points, their reprojections and the residuals to a PNG.

    :param result: a calibration result
    :param path: the PNG to write
    :param lines: (N,) CSV line numbers used to label outliers (default: point indices)
    """
    # The object-oriented API with an Agg canvas sets no global backend state.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    calib = result.calibration
    width, height = calib.image_width, calib.image_height
    figure = Figure(figsize=(12, 5), layout='constrained')
    FigureCanvasAgg(figure)
    image_ax, residual_ax = figure.subplots(1, 2, width_ratios=(3, 2))
    measured, reprojected = result.pixels, result.reprojected
    # Residuals are sub-pixel: draw the vectors magnified to about 3 % of the image width.
    typical = max(float(np.median(result.residuals_px)), 1e-6)
    gain = float(np.clip(0.03 * width / typical, 1.0, 1e4))
    image_ax.add_patch(_rectangle(width, height))
    image_ax.plot(measured[:, 0], measured[:, 1], 'o', ms=3, mfc='none', color='tab:blue',
                  label='measured')
    image_ax.plot(reprojected[:, 0], reprojected[:, 1], '+', ms=4, color='tab:orange',
                  label='reprojected')
    tips = measured + gain * (reprojected - measured)
    for start, tip, bad in zip(measured, tips, result.outliers):
        image_ax.plot((start[0], tip[0]), (start[1], tip[1]), '-', lw=0.8,
                      color='tab:red' if bad else 'tab:gray')
    labels = lines if lines is not None else np.arange(len(measured))
    for i in np.flatnonzero(result.outliers):
        image_ax.annotate(str(int(labels[i])) if result.mode != 'intrinsics' else '',
                          measured[i], color='tab:red', fontsize=7)
    image_ax.set_xlim(-0.05 * width, 1.05 * width)
    image_ax.set_ylim(1.05 * height, -0.05 * height)
    image_ax.set_aspect('equal')
    image_ax.set_xlabel('u [px]')
    image_ax.set_ylabel('v [px]')
    image_ax.set_title(f'{calib.camera_name}: {result.mode}, RMS {result.rms_px:.3f} px '
                       f'(residuals x{gain:.0f}, outliers red)', fontsize=10)
    image_ax.legend(loc='upper right', fontsize=8)

    if result.mode == 'intrinsics':
        assert result.image_rms_px is not None
        residual_ax.bar(np.arange(len(result.image_rms_px)), result.image_rms_px,
                        color='tab:blue')
        residual_ax.set_xlabel('image')
        residual_ax.set_ylabel('RMS reprojection error [px]')
    else:
        index = np.arange(len(result.residuals_px))
        colors = np.where(result.outliers, 'tab:red', 'tab:blue')
        residual_ax.bar(index, result.residuals_px, color=colors)
        residual_ax.set_xlabel('point (file order)')
        residual_ax.set_ylabel('residual [px]')
    residual_ax.axhline(result.outlier_threshold_px, color='tab:red', ls='--', lw=1,
                        label=f'outlier threshold {result.outlier_threshold_px:.2f} px')
    residual_ax.legend(fontsize=8)
    figure.savefig(os.fspath(path), dpi=100)


def _rectangle(width: int, height: int):
    from matplotlib.patches import Rectangle
    return Rectangle((-0.5, -0.5), width, height, fill=False, color='black', lw=1)
