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
``bringup``: the whole live pipeline in one process, without launch files.

Default: two virtual cameras (30 fps, camera 2 delayed by 1/60 s), each a
``camera_detector`` (capture and detection in one node, no image over DDS),
the fuser and the monitor, composed in one executor.  Each camera's source is
``--source virtual|file|device|topic`` or its own ``--camera NAME=SPEC``
(``/dev/videoN`` or an index: a device; ``virtual``; anything else: a video
file).  ``topic`` runs the ``detector`` on ``/<name>/image_raw`` of a driver
of your own.  ``--real`` is ``--source device``.  Cameras that are not
virtual need their calibrations, from ``--calibration NAME=FILE`` per camera
or the fuser's ``calibration_files`` in the params file (it refuses to start
on the simulated rig's calibration).  Virtual cameras take
``config/rig/<name>.yaml``, else the default rig's files in order
(``camera1``, ``camera2``, ``camera3``), so ``--cameras a b c`` runs three;
``--fps NAME=HZ`` and ``--phase NAME=S`` set their rates and phases (by
default the phases spread the shutters evenly).  Parameters come from
``config/bringup.yaml`` (or ``--params-file``); the options here override
them.  With ``--duration`` it stops by itself, prints the monitor's summary
and can write a plot (``--plot``).
"""

import argparse
import math
import os
import re
import sys
import time
from typing import List, Optional

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

from .camera_detector_node import CameraDetectorNode
from .detector_node import DetectorNode
from .fuser_node import FuserNode
from .monitor_node import MonitorNode
from .node_tools import (check_params_files, close, DEFAULT_EXECUTOR, EXECUTORS, init_context,
                         spin, STARTUP_ERRORS)
from ..cli.common import name_values
from ..errors import RigError
from ..fusion import METHOD_NAMES
from ..rig import check_camera_name, config_dir
from ..sim.scenarios import SCENARIOS

__all__ = ['SOURCES', 'build_nodes', 'build_parser', 'camera_sources', 'main', 'write_plot']

#: Per-camera sources: ``topic`` is the ``detector`` on a driver's ``image_raw``.
SOURCES = ('virtual', 'file', 'device', 'topic')
#: Frame rate of a virtual camera or requested from a device without ``--fps`` [Hz].
DEFAULT_FPS = 30.0
_DEVICE = re.compile(r'^(/dev/\S+|\d+)$')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``bringup``."""
    parser = argparse.ArgumentParser(
        prog='bringup', description='Run the pseudo stereo pipeline in one process.')
    parser.add_argument('--source', choices=SOURCES, default=None,
                        help='source of the cameras without their own --camera spec '
                             '(default: virtual)')
    parser.add_argument('--real', action='store_true', help='the same as --source device')
    parser.add_argument('--cameras', nargs='+', default=None,
                        help='camera names (default: the --camera names, else camera1 camera2)')
    parser.add_argument('--camera', action='append', default=[], metavar='NAME=SPEC',
                        help='a camera and its source, once per camera: /dev/videoN or an '
                             'index (device), virtual, or a video file')
    parser.add_argument('--calibration', action='append', default=[], metavar='NAME=FILE',
                        help="a camera's calibration YAML, once per camera (overrides the "
                             "fuser's calibration_files; required for cameras that are not "
                             'virtual unless the params file gives calibration_files; virtual '
                             'cameras render with it too)')
    parser.add_argument('--fps', action='append', default=[], metavar='NAME=HZ',
                        help=f'frame rate of a camera (virtual; requested from a device); '
                             f'default {DEFAULT_FPS:g}')
    parser.add_argument('--phase', action='append', default=[], metavar='NAME=S',
                        help='shutter delay of a virtual camera (or start offset of a video '
                             'file) [s]; default: shutters spread evenly')
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), default=None,
                        help='trajectory of the virtual cameras (default: the params file)')
    parser.add_argument('--method', choices=METHOD_NAMES, default=None,
                        help='fusion method (default: the params file)')
    parser.add_argument('--params-file', default=None,
                        help='ROS parameter file (default: config/bringup.yaml)')
    parser.add_argument('--duration', type=float, default=0.0,
                        help='stop after this many seconds and print a summary (0: run)')
    parser.add_argument('--plot', default=None,
                        help='write a PNG of trajectory and error here at the end')
    parser.add_argument('--executor', choices=EXECUTORS, default=DEFAULT_EXECUTOR,
                        help=f'rclpy executor (default: {DEFAULT_EXECUTOR}, '
                        'rclpy.experimental.EventsExecutor: the fastest in Python)')
    return parser


def _numbers(items: List[str], option: str, names: List[str], *, positive: bool):
    values = {}
    for name, text in name_values(items, option, names=names).items():
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise ValueError(f'{option} {name}={text}: expected a number '
                             f'{"> 0" if positive else ">= 0"}')
        values[name] = value
    return values


def camera_sources(options) -> List[dict]:
    """
    Resolve the cameras of the options: name, source, spec, calibration, fps, phase.

    :param options: parsed :func:`build_parser` options
    :return: one dict per camera, in order: ``name``, ``source`` (one of :data:`SOURCES`),
        ``spec`` (device or file; None), ``calibration`` (a file or None), ``fps``,
        ``phase_s``
    :raises ValueError: a malformed, unknown or repeated option, fewer than two cameras,
        a device or file source without its spec, or a virtual camera without a calibration
    """
    specs = [item.partition('=')[0] for item in options.camera]
    names = list(options.cameras or []) or [name for name in specs if name] or \
        ['camera1', 'camera2']
    if len(names) < 2:
        raise ValueError('need at least two cameras (--cameras or --camera NAME=SPEC)')
    if len(set(names)) != len(names):
        raise ValueError(f'camera names must be unique, got {" ".join(names)}')
    try:
        for name in names:
            check_camera_name(name)  # before a node takes it as its namespace
    except RigError as err:
        raise RigError(f'--cameras: {err}') from err
    given = name_values(options.camera, '--camera', what='SPEC', names=names)
    calibrations = name_values(options.calibration, '--calibration', what='FILE', names=names)
    fps = _numbers(options.fps, '--fps', names, positive=True)
    phases = _numbers(options.phase, '--phase', names, positive=False)
    default_source = 'device' if options.real else (options.source or 'virtual')
    if options.real and options.source not in (None, 'device'):
        raise ValueError(f'--real is --source device; it contradicts --source {options.source}')
    cameras = []
    for name in names:
        spec = given.get(name)
        if spec is None:
            source = default_source
        elif spec == 'virtual':
            source, spec = 'virtual', None
        else:
            source = 'device' if _DEVICE.match(spec) else 'file'
        if source in ('device', 'file') and spec is None:
            raise ValueError(f'camera {name}: source {source} needs its '
                             f'{"device" if source == "device" else "video file"}: --camera '
                             f'{name}={"/dev/videoN" if source == "device" else "FILE"}')
        cameras.append({'name': name, 'source': source, 'spec': spec,
                        'calibration': calibrations.get(name),
                        'fps': fps.get(name, DEFAULT_FPS), 'phase_s': phases.get(name)})
    real = [camera for camera in cameras if camera['source'] != 'virtual']
    if calibrations and any(camera['calibration'] is None for camera in real):
        missing = [camera['name'] for camera in real if camera['calibration'] is None]
        raise ValueError(f'--calibration: none for {", ".join(missing)} (give one per camera)')
    rig_dir = config_dir() / 'rig'
    for index, camera in enumerate(cameras):
        if camera['source'] != 'virtual' or camera['calibration']:
            continue
        for candidate in (rig_dir / f'{camera["name"]}.yaml', rig_dir / f'camera{index + 1}.yaml'):
            if candidate.is_file():
                camera['calibration'] = str(candidate)
                break
        else:
            raise ValueError(f'virtual camera {camera["name"]}: no calibration (give '
                             f'--calibration {camera["name"]}=FILE)')
    # Default phases spread the shutters of all cameras evenly over the fastest one's period.
    fastest = max(camera['fps'] for camera in cameras)
    for index, camera in enumerate(cameras):
        if camera['phase_s'] is None:
            camera['phase_s'] = index / (fastest * len(cameras)) if camera['source'] == \
                'virtual' else 0.0
    return cameras


def build_nodes(options, context, cameras: List[dict], nodes: list) -> None:
    """
    Create bringup's nodes: the fuser, a camera_detector (or detector) per camera, the monitor.

    :param options: parsed :func:`build_parser` options (``method``, ``scenario``)
    :param context: the rclpy context
    :param cameras: :func:`camera_sources` of the options
    :param nodes: the nodes are appended here as they are made, so the caller can destroy
        those made before an error
    :raises ValueError: cameras that are not virtual without real calibrations; the nodes'
        start-up errors
    """
    names = [camera['name'] for camera in cameras]
    # Parameter services multiply the executor's wait set; bringup's nodes are set by files.
    common = {'context': context, 'start_parameter_services': False}
    fuser_overrides = [Parameter('camera_names', value=names)]
    if any(camera['calibration'] for camera in cameras):
        files = [camera['calibration'] or '' for camera in cameras]
        if all(files):
            fuser_overrides.append(Parameter('calibration_files', value=files))
    if options.method:
        fuser_overrides.append(Parameter('method', value=options.method))
    # The fuser first: it subscribes before the first image point is published.
    fuser = FuserNode(parameter_overrides=fuser_overrides, **common)
    nodes.append(fuser)
    if fuser.default_calibration and any(c['source'] != 'virtual' for c in cameras):
        # The fuser's default is the simulated rig: real cameras would be fused with a wrong
        # geometry, silently.
        raise ValueError("cameras that are not virtual need the real cameras' calibrations: "
                         'give --calibration NAME=FILE per camera, or calibration_files in '
                         'the fuser section of the params file')
    files = list(fuser.get_parameter('calibration_files').value or [])
    files = files if len(files) == len(names) and all(files) else [None] * len(names)
    starts = []
    for index, camera in enumerate(cameras):
        name, source = camera['name'], camera['source']
        calibration = camera['calibration'] or files[index]
        if source == 'topic':
            nodes.append(DetectorNode(namespace=name, **common))
            continue
        overrides = [Parameter('source', value=source), Parameter('seed', value=index),
                     Parameter('fps', value=float(camera['fps']))]
        if calibration:
            overrides.append(Parameter('calibration_file', value=calibration))
        if source == 'virtual':
            overrides.append(Parameter('phase_s', value=float(camera['phase_s'])))
            if options.scenario:
                overrides.append(Parameter('scenario', value=options.scenario))
        elif source == 'file':
            overrides.append(Parameter('video_file', value=camera['spec']))
        else:
            overrides.append(Parameter('device', value=camera['spec']))
        nodes.append(CameraDetectorNode(namespace=name, parameter_overrides=overrides,
                                        start=False, **common))
        starts.append((nodes[-1], source, camera['phase_s']))
    nodes.append(MonitorNode(parameter_overrides=[
        Parameter('camera_names', value=names),
        Parameter('calibration_files',
                  value=[str(f) for f in files] if all(files) else [''])], **common))
    # Every node exists (building them takes a while on a loaded machine): start the cameras
    # together, virtual and file ones with one epoch, a round millisecond soon after now.
    epoch = time.time_ns() + 300_000_000
    epoch -= epoch % 1_000_000
    for node, source, phase_s in starts:
        if source == 'virtual':
            node.start(epoch_ns=epoch)  # the phase is the node's phase_s
        elif source == 'file':
            node.start(epoch_ns=epoch + round(phase_s * 1e9))
        else:
            node.start()


def write_plot(monitor: MonitorNode, path: str) -> None:
    """
    Write a PNG: the trajectory (truth, paper, naive) and the 3D error over time.

    :param monitor: the monitor after the run
    :param path: the PNG file (its directory is created)
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    def series(points):
        stamps = np.array(sorted(points), dtype=np.int64)
        return stamps, np.array([points[s] for s in stamps], dtype=float).reshape(-1, 3)

    def broken(stamps, values):
        """Insert NaN rows where a gap of over 0.1 s (a pause between flights) would be drawn."""
        gaps = np.flatnonzero(np.diff(stamps) > 100_000_000) + 1
        return np.insert(values.astype(float), gaps, np.nan, axis=0)

    truth_t, truth = series(monitor.truth)
    truth = broken(truth_t, truth)
    t0 = truth_t[0] if len(truth_t) else 0
    fig = plt.figure(figsize=(12, 5))
    ax3d = fig.add_subplot(1, 2, 1, projection='3d')
    ax3d.plot(*truth.T, 'k-', lw=1, label='truth')
    colours = {'paper': 'tab:blue', 'naive': 'tab:red'}
    errors_ax = fig.add_subplot(1, 2, 2)
    for method, points in (('paper', monitor.paper), ('naive', monitor.naive_estimates)):
        _, xyz = series(points)
        if len(xyz):
            ax3d.plot(*xyz.T, '.', ms=2, color=colours[method], label=method)
        errors = monitor.errors(points)
        if len(errors):
            line = broken(errors[:, 0].astype(np.int64), errors)
            errors_ax.plot((line[:, 0] - t0) / 1e9, line[:, 1] * 1e3, '.-', ms=2, lw=0.5,
                           color=colours[method],
                           label=f'{method}: mean {errors[:, 1].mean() * 1e3:.2f} mm')
    ax3d.set_xlabel('x [m]')
    ax3d.set_ylabel('y [m]')
    ax3d.set_zlabel('z [m]')
    ax3d.set_title('trajectory')
    ax3d.legend()
    errors_ax.set_yscale('log')
    errors_ax.set_xlabel('time [s]')
    errors_ax.set_ylabel('3D error [mm]')
    errors_ax.set_title('error against ground truth at each shutter event')
    errors_ax.legend()
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _print_summary(monitor: MonitorNode, cameras: List[CameraDetectorNode],
                   seconds: float) -> None:
    summary = monitor.summary()
    print(f'bringup: ran {seconds:.1f} s')
    for key, value in summary['rates'].items():
        print(f'  rate {key:<24s} {value:7.2f} Hz')
    points = sum(monitor.counts[f'{name}/ball/image_point'] for name in monitor.names)
    positions = monitor.counts['ball/position']
    rates = [node.get_parameter('fps').value for node in cameras
             if node.get_parameter('source').value == 'virtual']
    in_flight = f'{sum(rates):g} Hz in flight; ' if rates and len(rates) == len(cameras) else ''
    print(f'  /ball/position messages per detected shutter event: {positions} / {points} '
          f'({in_flight}the first 3 events of a flight warm up, and between flights the ball '
          'is out of view)')
    for method in ('paper', 'naive'):
        matched = summary['matched'][method]
        error = (f'{summary["error_mm"][method]:9.3f} mm' if matched else '      n/a   ')
        print(f'  mean 3D error {method:<6s} {error} ({matched} estimates with ground truth)')
    p50, p90, p99 = summary['latency_ms']
    print(f'  latency shutter stamp -> /ball/position: p50 {p50:.2f} ms, p90 {p90:.2f} ms, '
          f'p99 {p99:.2f} ms')
    p50, p90, p99 = summary['point_latency_ms']
    print(f'  latency shutter stamp -> image point:    p50 {p50:.2f} ms, p90 {p90:.2f} ms, '
          f'p99 {p99:.2f} ms')
    for node in cameras:
        values = node.diagnostics()
        print(f'  {node.camera_name}: {values["frames"]} frames, {values["image points"]} '
              f'points, {values["failures"]} source failures; shutter -> frame available p50 '
              f'{values["shutter -> frame available p50 [ms]"]:.2f} ms, frame available -> '
              f'image point p50 {values["frame available -> image point p50 [ms]"]:.2f} ms')


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``bringup``; return the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if '--ros-args' in argv:
        split = argv.index('--ros-args')
        argv, ros_args = argv[:split], argv[split:]
    else:
        ros_args = []
    options = build_parser().parse_args(argv)
    params_file = options.params_file or str(config_dir() / 'bringup.yaml')
    if not os.path.isfile(params_file):
        print(f'bringup: error: --params-file {params_file}: no such file', file=sys.stderr)
        return 2
    try:
        cameras = camera_sources(options)
    except ValueError as err:
        print(f'bringup: error: {err}', file=sys.stderr)
        return 2
    context = rclpy.Context()
    init_args = ['bringup', '--ros-args', '--params-file', params_file] + ros_args[1:]
    if not init_context(init_args, context=context, name='bringup'):
        return 1
    nodes = []
    try:
        try:
            build_nodes(options, context, cameras, nodes)
        except STARTUP_ERRORS as err:
            print(f'bringup: error: cannot start: {err}', file=sys.stderr)
            return 1
        # The package's own bringup.yaml has sections for both camera modes (camera_detector,
        # detector on a driver's topic): only the files a user gave are checked.
        check_params_files(nodes, init_args if options.params_file else ['bringup'] + ros_args)
        started = time.monotonic()
        spin(nodes, executor=options.executor, context=context,
             duration_s=options.duration if options.duration > 0 else None)
        monitor = next((node for node in nodes if isinstance(node, MonitorNode)), None)
        if monitor is not None:
            _print_summary(monitor, [n for n in nodes if isinstance(n, CameraDetectorNode)],
                           time.monotonic() - started)
            if options.plot:
                write_plot(monitor, options.plot)
                print(f'  plot: {options.plot}')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close(nodes, context=context)
    return 0


if __name__ == '__main__':
    sys.exit(main())
