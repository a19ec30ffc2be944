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

Default: two virtual cameras (30 fps, camera 2 delayed by 1/60 s), a
detector per camera, the fuser and the monitor, composed in one executor.
``--real`` runs only the detectors and the fuser on real camera topics
(``/<name>/image_raw``); it needs the real cameras' calibrations, from
``--calibration NAME=FILE`` per camera or the fuser's ``calibration_files``
in the params file (it refuses to start on the simulated rig's
calibration).  Parameters come from ``config/bringup.yaml``
(or ``--params-file``); the options here override them.  With
``--duration`` it stops by itself, prints the monitor's summary and can
write a plot (``--plot``).
"""

import argparse
import os
import sys
import time
from typing import List, Optional

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

from .detector_node import DetectorNode
from .fuser_node import FuserNode
from .monitor_node import MonitorNode
from .node_tools import (check_params_files, close, DEFAULT_EXECUTOR, EXECUTORS, init_context,
                         spin, STARTUP_ERRORS)
from .virtual_camera_node import VirtualCameraNode
from ..fusion import METHODS
from ..sim.scenarios import config_dir, SCENARIOS

__all__ = ['build_parser', 'main', 'write_plot']


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``bringup``."""
    parser = argparse.ArgumentParser(
        prog='bringup', description='Run the pseudo stereo pipeline in one process.')
    parser.add_argument('--real', action='store_true',
                        help='no virtual cameras: detectors and fuser on /<name>/image_raw')
    parser.add_argument('--cameras', nargs='+', default=['camera1', 'camera2'],
                        help='camera names (default: camera1 camera2)')
    parser.add_argument('--calibration', action='append', default=[], metavar='NAME=FILE',
                        help="a camera's calibration YAML, once per camera (overrides the "
                             "fuser's calibration_files; required with --real unless the "
                             'params file gives calibration_files; without --real the virtual '
                             'cameras render with it too)')
    parser.add_argument('--scenario', choices=sorted(SCENARIOS), default=None,
                        help='trajectory of the virtual cameras (default: the params file)')
    parser.add_argument('--method', choices=METHODS, default=None,
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


def _calibrations(options) -> dict:
    """Return ``{camera name: file}`` from ``--calibration NAME=FILE``; raise ValueError."""
    files = {}
    for item in options.calibration:
        name, sep, path = item.partition('=')
        if not sep or not name or not path:
            raise ValueError(f'--calibration {item}: expected NAME=FILE')
        if name not in options.cameras:
            raise ValueError(f'--calibration {item}: {name} is not one of --cameras '
                             f'{" ".join(options.cameras)}')
        if name in files:
            raise ValueError(f'--calibration: {name} given twice')
        files[name] = path
    if files and set(files) != set(options.cameras):
        missing = [name for name in options.cameras if name not in files]
        raise ValueError(f'--calibration: none for {", ".join(missing)} (give one per camera)')
    return files


def _nodes(options, context, calibrations: dict, nodes: list) -> None:
    """Create the nodes into ``nodes`` (so the caller destroys those made before an error)."""
    names = options.cameras
    # Parameter services multiply the executor's wait set; bringup's nodes are set by files.
    common = {'context': context, 'start_parameter_services': False}
    if not options.real:
        fps, epoch = 30.0, time.time_ns() + 500_000_000
        epoch -= epoch % 1_000_000  # a round millisecond, easy to read in stamps
        for index, name in enumerate(names):
            rig_file = calibrations.get(name, str(config_dir() / 'rig' / f'{name}.yaml'))
            overrides = [Parameter('calibration_file', value=rig_file),
                         Parameter('phase_s', value=index / (fps * len(names))),
                         Parameter('epoch_ns', value=epoch),
                         Parameter('seed', value=index)]
            if options.scenario:
                overrides.append(Parameter('scenario', value=options.scenario))
            nodes.append(VirtualCameraNode(namespace=name, parameter_overrides=overrides,
                                           **common))
    for name in names:
        nodes.append(DetectorNode(namespace=name, **common))
    fuser_overrides = [Parameter('camera_names', value=list(names))]
    if calibrations:
        fuser_overrides.append(Parameter('calibration_files',
                                         value=[calibrations[name] for name in names]))
    if options.method:
        fuser_overrides.append(Parameter('method', value=options.method))
    fuser = FuserNode(parameter_overrides=fuser_overrides, **common)
    nodes.append(fuser)
    if options.real and fuser.default_calibration:
        # The fuser's default is the simulated rig: real cameras would be fused with a wrong
        # geometry, silently.
        raise ValueError("--real needs the real cameras' calibrations: give --calibration "
                         'NAME=FILE per camera, or calibration_files in the fuser section of '
                         'the params file')
    if not options.real:
        nodes.append(MonitorNode(parameter_overrides=[Parameter('camera_names',
                                                                value=list(names))],
                                 **common))


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


def _print_summary(monitor: MonitorNode, seconds: float) -> None:
    summary = monitor.summary()
    print(f'bringup: ran {seconds:.1f} s')
    for key, value in summary['rates'].items():
        print(f'  rate {key:<24s} {value:7.2f} Hz')
    points = sum(monitor.counts[f'{name}/ball/image_point'] for name in monitor.names)
    positions = monitor.counts['ball/position']
    print(f'  /ball/position messages per detected shutter event: {positions} / {points} '
          '(60 Hz in flight; the first 3 events of a flight warm up, and between flights '
          'the ball is out of view)')
    for method in ('paper', 'naive'):
        print(f'  mean 3D error {method:<6s} {summary["error_mm"][method]:9.3f} mm '
              f'({summary["matched"][method]} estimates with ground truth)')
    p50, p90, p99 = summary['latency_ms']
    print(f'  latency image stamp -> /ball/position: p50 {p50:.2f} ms, p90 {p90:.2f} ms, '
          f'p99 {p99:.2f} ms')
    p50, p90, p99 = summary['point_latency_ms']
    print(f'  latency image stamp -> image point:    p50 {p50:.2f} ms, p90 {p90:.2f} ms, '
          f'p99 {p99:.2f} ms')


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``bringup``; return the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if '--ros-args' in argv:
        split = argv.index('--ros-args')
        argv, ros_args = argv[:split], argv[split:]
    else:
        ros_args = []
    options = build_parser().parse_args(argv)
    if len(options.cameras) < 2:
        print('bringup: error: --cameras needs at least two names', file=sys.stderr)
        return 2
    params_file = options.params_file or str(config_dir() / 'bringup.yaml')
    if not os.path.isfile(params_file):
        print(f'bringup: error: --params-file {params_file}: no such file', file=sys.stderr)
        return 2
    try:
        calibrations = _calibrations(options)
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
            _nodes(options, context, calibrations, nodes)
        except STARTUP_ERRORS as err:
            print(f'bringup: error: cannot start: {err}', file=sys.stderr)
            return 1
        check_params_files(nodes, init_args)
        started = time.monotonic()
        spin(nodes, executor=options.executor, context=context,
             duration_s=options.duration if options.duration > 0 else None)
        monitor = next((node for node in nodes if isinstance(node, MonitorNode)), None)
        if monitor is not None:
            _print_summary(monitor, time.monotonic() - started)
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
