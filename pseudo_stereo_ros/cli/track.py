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
``pseudo_stereo track``: run a method offline on recorded observations (CSV or bag).

With ``--bag`` the observations are the bag's ``/<camera>/ball/image_point``
topics; a camera without one but with ``/<camera>/image_raw`` images gets
the core :class:`~pseudo_stereo_ros.detection.BallDetector` run over its
images first (one detector per camera, frames in bag order, as the detector
node does live).  Either way the estimates come from
:meth:`~pseudo_stereo_ros.fusion.Fuser.process`, the one offline code path, and go to
``--output`` (CSV) and/or ``--output-bag`` (``/ball/position``,
PointStamped in ``--world-frame``, stamped with the shutter stamp).
"""

from pathlib import Path
import sys

import cv2
import numpy as np

from . import UsageError
from .common import (add_camera_argument, cameras_from_args, seconds_to_ns,
                     time_offsets_from_args)
from ..detection import BallDetector
from ..errors import FuserConfigError
from ..evaluation.table1 import score
from ..formats.bagio import (bag_topics, BagError, check_bag_stamps, GROUND_TRUTH_TOPIC,
                             image_point_topic, image_topic, read_images,
                             read_observations as read_bag_observations, read_positions,
                             write_estimates as write_bag_estimates)
from ..formats.csv_io import read_observations, read_truth, write_estimates
from ..formats.yaml_io import read_yaml
from ..fusion import (DEFAULT_IMAGE_MARGIN, DEFAULT_MAX_GAP_NS, DEFAULT_MAX_SPEED_MPS,
                      DEFAULT_SYNC_TOLERANCE_NS, make_fuser, METHOD_NAMES)
from ..offsets import apply_time_offsets, camera_time_offsets
from ..records import Observation

NAME = 'track'
HELP = ('run the fuser offline on observations (stamp_ns,camera,u,v CSV, or image points or '
        'images in a bag) -> estimates CSV and/or bag')

#: Parameters of the detector node that configure :class:`BallDetector`.
DETECTOR_PARAMETERS = ('hsv_lower', 'hsv_upper', 'mono_threshold', 'min_area_px',
                       'max_area_px', 'open_kernel_px', 'choice', 'search_window_px')
# Parameters of the detector node that do not concern detection itself.
_NODE_ONLY_PARAMETERS = ('error_throttle_s', 'use_sim_time')


def add_arguments(parser) -> None:
    """Add this command's options."""
    add_camera_argument(parser)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument('--input', metavar='OBS.csv',
                        help='observations with header stamp_ns,camera,u,v (any row order)')
    source.add_argument('--bag', metavar='IN',
                        help='a ROS 2 bag (directory, .mcap or .db3) with /<camera>/ball/'
                             'image_point (PointStamped) or /<camera>/image_raw (Image, the '
                             'detector runs first) per camera')
    parser.add_argument('--output', metavar='EST.csv',
                        help='estimates with header stamp_ns,camera,x,y,z, in stamp order')
    parser.add_argument('--output-bag', metavar='OUT',
                        help='a new bag (mcap) with the estimates on /ball/position')
    parser.add_argument('--method', choices=METHOD_NAMES, default='paper')
    parser.add_argument('--time-offset', action='append', default=[], metavar='NAME=SECONDS',
                        help="add SECONDS to camera NAME's stamps (overrides the time_offset_s "
                             'of its calibration file; repeat per camera)')
    parser.add_argument('--sync-tolerance', type=float, default=DEFAULT_SYNC_TOLERANCE_NS / 1e9,
                        metavar='S', help='observations closer than this are simultaneous '
                                          '(default: %(default)s s)')
    parser.add_argument('--max-gap', type=float, default=DEFAULT_MAX_GAP_NS / 1e9, metavar='S',
                        help='upper bound of the longest gap bridged by interpolation; each '
                             'camera uses at most 4.5 of its measured frame periods (default: '
                             '%(default)s s)')
    parser.add_argument('--image-margin', type=float, default=DEFAULT_IMAGE_MARGIN,
                        metavar='F', help='drop points farther outside the image than this '
                                          'fraction of its size (default: %(default)s; inf: '
                                          'no check)')
    parser.add_argument('--max-speed', type=float, default=DEFAULT_MAX_SPEED_MPS,
                        metavar='MPS', help='drop estimates implying a faster motion '
                                            '(default: %(default)s m/s; 0: no check)')
    parser.add_argument('--workspace-min', type=float, nargs=3, metavar=('X', 'Y', 'Z'),
                        help='lower corner of the workspace [m]: drop estimates outside '
                             '(default: unbounded)')
    parser.add_argument('--workspace-max', type=float, nargs=3, metavar=('X', 'Y', 'Z'),
                        help='upper corner of the workspace [m] (default: unbounded)')
    parser.add_argument('--truth', metavar='TRUTH.csv',
                        help='optional ground truth (stamp_ns,x,y,z): print the error (with '
                             '--bag, a /ball/ground_truth topic in the bag is used by default)')
    parser.add_argument('--world-frame', default='world', metavar='FRAME',
                        help='frame_id of /ball/position in --output-bag (default: %(default)s)')
    parser.add_argument('--detector-params', metavar='FILE',
                        help='ROS parameter file with a detector section (as '
                             'config/detector.yaml) for bags of images (default: the '
                             'defaults of the detector node)')


def detector_parameters(path) -> dict:
    """
    Read the ``detector`` section of a ROS parameter file.

    :param path: a YAML file such as ``config/detector.yaml``: a top-level key ``detector``
        or ending in ``/detector`` (``/**/detector``) holding ``ros__parameters``
    :return: keyword arguments of :class:`BallDetector`
    :raises UsageError: unreadable file, no detector section, unknown parameter
    """
    try:
        document, _ = read_yaml(path, error=UsageError)
    except UsageError as err:
        raise UsageError(f'--detector-params {err}') from err
    sections = []
    if isinstance(document, dict):
        sections = [value['ros__parameters'] for key, value in document.items()
                    if str(key).split('/')[-1] == 'detector' and isinstance(value, dict)
                    and isinstance(value.get('ros__parameters'), dict)]
    if not sections:
        raise UsageError(f'--detector-params {path}: no detector section with ros__parameters '
                         '(expected as in config/detector.yaml)')
    parameters = {}
    for key, value in sections[0].items():
        if key in DETECTOR_PARAMETERS:
            parameters[key] = value
        elif key not in _NODE_ONLY_PARAMETERS:
            raise UsageError(f'--detector-params {path}: unknown detector parameter {key!r} '
                             f'(known: {", ".join(DETECTOR_PARAMETERS)})')
    return parameters


def _detect(bag, camera: str, parameters: dict, path_for_errors: str) -> tuple:
    """
    Run a detector over a camera's images.

    :return: ``(observations, images, unusable, first_problem)``: the detections, the number
        of images and of unusable ones, and why the first unusable image was (None if none)
    """
    try:
        detector = BallDetector(**parameters)
    except (TypeError, ValueError) as err:
        raise UsageError(f'{path_for_errors}: {err}') from err
    observations, images, unusable, first_problem = [], 0, 0, None
    for stamp_ns, encoding, pixels, problem in read_images(bag, image_topic(camera)):
        images += 1
        found = None
        if pixels is not None:
            try:
                found = detector.detect(pixels, encoding)
            except (ValueError, cv2.error) as err:  # as the detector node: dropped, counted
                problem = ' '.join(str(err).split())
        if problem is not None:
            unusable += 1
            first_problem = first_problem or problem
        elif found is not None:
            observations.append(Observation(camera, stamp_ns, found[0], found[1]))
    return observations, images, unusable, first_problem


def bag_observations(bag, camera_names, detector_params: dict) -> tuple:
    """
    Read or detect the observations of the named cameras in a bag.

    :param bag: the bag
    :param camera_names: the cameras, each with ``/<name>/ball/image_point`` (used when
        present) or ``/<name>/image_raw`` (the detector runs over it)
    :param detector_params: :class:`BallDetector` keyword arguments for image topics
    :return: ``(observations, notes)``: notes are lines for the user about detection
    :raises BagError: missing topics, wrong types, a damaged bag, a camera whose every image
        is unusable (an unsupported encoding, a size that does not fit the buffer)
    """
    topics = bag_topics(bag)
    point_cameras, image_cameras = [], []
    for name in camera_names:
        if image_point_topic(name) in topics:
            point_cameras.append(name)
        elif image_topic(name) in topics:
            image_cameras.append(name)
        else:
            raise BagError(f'{bag}: no topic {image_point_topic(name)} or {image_topic(name)} '
                           f'for camera {name} (the bag has: '
                           f'{", ".join(sorted(topics)) or "no topics"})')
    observations = read_bag_observations(bag, point_cameras) if point_cameras else []
    notes = []
    for name in image_cameras:
        found, images, unusable, problem = _detect(bag, name, detector_params,
                                                   '--detector-params')
        if not images:
            raise BagError(f'{bag}: no messages on {image_topic(name)}')
        if unusable == images:
            raise BagError(f'{bag}: camera {name}: all {images} images of {image_topic(name)} '
                           f'are unusable, the first because: {problem}')
        notes.append(f'{name}: ball found in {len(found)} of {images} images of '
                     f'{image_topic(name)}' + (f' ({unusable} unusable)' if unusable else ''))
        observations.extend(found)
    return observations, notes


def run(args) -> int:
    """Run the command."""
    if args.output is None and args.output_bag is None:
        raise UsageError('give --output EST.csv and/or --output-bag OUT')
    if args.output_bag is not None and Path(args.output_bag).exists():
        raise UsageError(f'--output-bag {args.output_bag}: exists already, not overwriting')
    cameras = cameras_from_args(args.camera)
    offsets = camera_time_offsets(cameras, time_offsets_from_args(args.time_offset, cameras))
    options = {'method': args.method,
               'sync_tolerance_ns': seconds_to_ns(args.sync_tolerance, '--sync-tolerance'),
               'max_gap_ns': seconds_to_ns(args.max_gap, '--max-gap'),
               'image_margin': args.image_margin, 'max_speed_mps': args.max_speed,
               'workspace_min_m': args.workspace_min, 'workspace_max_m': args.workspace_max}
    try:
        fuser = make_fuser(cameras, **options)
    except FuserConfigError as err:
        raise UsageError(f'fuser options (--method, --sync-tolerance, --max-gap, --image-margin, '
                         f'--max-speed, --workspace-min/max): {err}') from err
    notes = []
    truth = read_truth(args.truth) if args.truth else None
    truth_name = args.truth
    if args.input is not None:
        observations = read_observations(args.input, cameras)
        source = args.input
    else:
        parameters = (detector_parameters(args.detector_params)
                      if args.detector_params else {})
        observations, notes = bag_observations(args.bag, list(cameras), parameters)
        source = args.bag
        if truth is None and GROUND_TRUTH_TOPIC in bag_topics(args.bag):
            positions = read_positions(args.bag, GROUND_TRUTH_TOPIC)
            truth = _truth_arrays(positions)
            truth_name = f'{args.bag} {GROUND_TRUTH_TOPIC}'
    if any(offsets.values()):
        # One boundary: stamps go on the common clock before any method sees them.
        observations = apply_time_offsets(observations, offsets)
        notes.append('time offsets applied: ' + ', '.join(
            f'{name} {value * 1e3:+.3f} ms' for name, value in offsets.items()))
    estimates = fuser.process(observations)
    result = None
    if truth is not None and (estimates or args.truth):
        try:  # before writing anything: a failed run leaves no output
            result = score(estimates, *truth)
        except ValueError as err:
            raise UsageError(f'truth {truth_name}: {err}') from err
    if args.output_bag is not None:  # before writing anything
        check_bag_stamps(args.output_bag, (e.stamp_ns for e in estimates))
    targets = []
    if args.output is not None:
        write_estimates(args.output, estimates)
        targets.append(args.output)
    if args.output_bag is not None:
        write_bag_estimates(args.output_bag, estimates, frame_id=args.world_frame)
        targets.append(f'{args.output_bag} (/ball/position)')
    for note in notes:
        print(note, file=sys.stderr)
    stats = fuser.stats
    dropped = ', '.join(f'{key} {count}' for key, count in fuser.dropped().items())
    if stats['outlier'] or stats['breaks']:
        dropped += (', ' if dropped else '') + (f'not fitted (outliers) {stats["outlier"]}, '
                                                f'impacts {stats["breaks"]}')
    print(f'{len(observations)} observations from {source} -> {len(estimates)} estimates '
          f'({args.method}) written to {" and ".join(targets)}'
          + (f'; no estimate: {dropped}' if dropped else ''), file=sys.stderr)
    if result is not None:
        print(f'error against {truth_name}: per-coordinate MAE {result.mae_mm:.3f} mm, '
              f'mean 3D distance {result.distance_mm:.3f} mm over {result.count} estimates')
    return 0


def _truth_arrays(positions) -> tuple:
    """Return ``(stamps, points)`` arrays of ``(stamp_ns, x, y, z)`` rows, sorted, unique."""
    rows = sorted({row[0]: row for row in positions}.values())
    return (np.array([row[0] for row in rows], dtype=np.int64),
            np.array([row[1:] for row in rows], dtype=float).reshape(-1, 3))
