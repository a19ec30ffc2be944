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
``bench_pipeline``: how fast the live pipeline is, beside a baseline measured in the same run.

Each measured quantity is printed as median and 90th percentile [ms], with
its target and, on the row below, a baseline measured in the same run on
the same inputs; the ratio (median / baseline median) is the number to
compare between machines and runs:

1. the detector core per 640x480 frame, full frame and with the search
   window (paper: 2.6 ms image analysis); baseline: ``cv2.cvtColor``
   BGR->HSV of the full frame, the least a full-frame colour detector does.
   Frames back to back keep the caches warm; a camera's detector runs once
   per frame period, so the window is also timed with a frame period of
   sleep before each frame (cold caches: what a camera_detector pays), and
   with a warm-up on the previous frame 2 ms before it (what it does);
2. the fuser node from receiving an image point to publishing its estimate
   (in-process, reorder window 0, the default); baseline: the core
   ``Fuser.update`` alone on the same observations, so the ratio is the
   node's overhead;
3. end to end on loopback, image stamp to ``/ball/position``: the
   ``detector`` (one per camera) and ``fuser`` console scripts run as
   separate processes; this process publishes rendered images stamped with
   the wall clock at publication and receives the positions (paper: 4.13 ms
   from capture to 3D); baseline: image stamp to the same image received by
   a bare subscriber in another process over the same DDS set-up (the
   transport), so the difference is the pipeline's own cost;
4. ``camera_detector`` processes (virtual source: capture and detection in
   one process, no image over DDS) feeding a fuser: shutter stamp ->
   ``/ball/position`` published (target: median 1.5 ms, p99 5 ms) and frame
   available -> image point (target 1 ms); baseline: a bare PointStamped hop
   between processes in the same run; and where each millisecond goes.
5. the fuser node under load, 2 x 1,000 Hz image points (2,000 messages/s)
   from another process, the fuser pinned to one core
   (:mod:`~pseudo_stereo_ros.ros.bench_load`): source stamp ->
   ``/ball/position`` received, with inputs and outputs lost, the CPU share
   of the fuser and its resident memory; baseline: a bare relay node
   (subscribe, publish the same message) on the same core and executor at
   the same rate, in the same run.  Target: p99 <= 2 ms, nothing lost.
   ``--soak 600`` runs only this row for ten minutes and prints the fuser's
   resident memory every minute.

Absolute numbers depend on the machine and its load; compare the ratios.
"""

import argparse
import copy
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time
from typing import List, Optional, Sequence, Tuple

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
import rclpy
from rclpy.logging import LoggingSeverity
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

from .bench_load import bench_load, LOAD_RATE_HZ, rss_growth, TARGET_P99_MS
from .fuser_node import FuserNode
from .messages import (array_to_image, decode_point, ns_to_stamp, observation_to_point,
                       stamp_to_ns)
from .node_tools import close, DEFAULT_EXECUTOR, EXECUTORS, make_executor, spin
from .processes import start_python, start_script, stop_processes
from ..detection import BallDetector
from ..rig import config_dir
from ..sim.rendering import BallRenderer
from ..sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, make_scenario, observe, shutter_stamps,
                             truth_at)

__all__ = ['bench_camera_detectors', 'hop_probe_main', 'main', 'print_camera_detector_rows',
           'transport_probe_main']

PAPER_IMAGE_ANALYSIS_MS = 2.6
PAPER_CAPTURE_TO_3D_MS = 4.13
TARGETS_MS = {'window': 1.0, 'full': 3.0, 'fuser': 0.5, 'end_to_end': 5.0,
              'camera_detector': 1.0, 'shutter_to_position': 1.5,
              'shutter_to_position_p99': 5.0}
#: Run sizes: frames (detector), image points (fuser), seconds of end-to-end streaming and of
#: the 2 x 1,000 Hz load.
FULL_RUN = {'frames': 88, 'points': 300, 'seconds': 5.0, 'load_seconds': 10.0}
QUICK_RUN = {'frames': 20, 'points': 60, 'seconds': 1.0, 'load_seconds': 1.0}
FPS = 30.0
#: Longest wait for the node processes to connect (every endpoint matched) [s].
CONNECT_TIMEOUT_S = 30.0

_LABEL_WIDTH = 46


def _stats(seconds) -> Tuple[float, float]:
    """Return (median, p90) [ms] of durations [s] (NaN when there are none)."""
    ms = np.asarray(seconds, dtype=float) * 1e3
    if not ms.size:
        return float('nan'), float('nan')
    return float(np.median(ms)), float(np.percentile(ms, 90))


def _header() -> str:
    return (f'  {"quantity":<{_LABEL_WIDTH}s}{"n":>6s}{"median":>9s}{"p90":>9s}  '
            f'{"target":<13s}{"ratio":>8s}')


def _row(label: str, seconds: Sequence[float], *, target_ms: Optional[float] = None,
         baseline: Optional[Sequence[float]] = None, extra: str = '',
         target_p99_ms: Optional[float] = None) -> str:
    """
    Return one table row: n, median and p90 [ms], the target verdict and the baseline ratio.

    :param label: what was measured
    :param seconds: the measured durations [s]
    :param target_ms: the target for the median [ms]; None for a baseline row
    :param baseline: durations [s] of the baseline; the ratio is median / baseline median
    :param extra: text after the ratio
    :param target_p99_ms: a target for the 99th percentile instead [ms]
    :return: the row
    """
    median, p90 = _stats(seconds)
    target = ''
    if target_ms is not None:
        target = f'<= {target_ms:g} ' + ('ok' if median <= target_ms else 'OVER')
    elif target_p99_ms is not None:
        p99 = float(np.percentile(np.asarray(seconds) * 1e3, 99)) if len(seconds) else np.nan
        target = f'p99 <= {target_p99_ms:g} ' + ('ok' if p99 <= target_p99_ms else 'OVER')
    ratio = ''
    if baseline is not None:
        base = _stats(baseline)[0]
        ratio = f'{median / base:.2f}x' if base > 0 else 'n/a'
    return (f'  {label:<{_LABEL_WIDTH}s}{len(seconds):>6d}{median:>9.3f}{p90:>9.3f}  '
            f'{target:<13s}{ratio:>8s}{extra}').rstrip()


def _frame_points(count: int) -> np.ndarray:
    """Return (count, 3) true positions [m] at camera 1's shutters, the spiral repeated."""
    scenario = make_scenario('spiral')
    points = truth_at(scenario, shutter_stamps(FPS, scenario.duration_s))
    return np.resize(points, (count, 3))


def _renderers():
    cameras = default_rig()
    return cameras, [BallRenderer(camera, noise_std=2.0, seed=i)
                     for i, camera in enumerate(cameras)]


def bench_detector(count: int) -> dict:
    """
    Time the detector core and its baseline on the same rendered frames.

    Each frame is timed with all three in turn, so a change of load on the
    machine affects them alike.  Then the window again, frame by frame at
    the camera's pace: a frame period of sleep before each (``cold``), and a
    warm-up on the previous frame 2 ms before each (``warmed``), as
    ``camera_detector`` does.

    :param count: frames (640x480 bgr8)
    :return: per-frame durations [s]: ``full``, ``window`` (48 px), ``baseline``
        (``cv2.cvtColor`` BGR->HSV of the full frame), ``cold`` and ``warmed`` (48 px)
    """
    _, renderers = _renderers()
    images = [renderers[0].render(p) for p in _frame_points(count)]
    detectors = {'full': BallDetector(search_window_px=0),
                 'window': BallDetector(search_window_px=48)}
    result = {'baseline': [], 'full': [], 'window': []}
    cv2.cvtColor(images[0], cv2.COLOR_BGR2HSV)  # warm caches
    for detector in detectors.values():
        detector.detect(images[0], 'bgr8')
    for image in images:
        start = time.perf_counter()
        cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
        result['baseline'].append(time.perf_counter() - start)
        for key, detector in detectors.items():
            start = time.perf_counter()
            detector.detect(image, 'bgr8')
            result[key].append(time.perf_counter() - start)
    lead_s = 0.002
    for key in ('cold', 'warmed'):
        detector = BallDetector(search_window_px=48)
        result[key] = []
        for previous, image in zip([images[0]] + images[:-1], images):
            if key == 'cold':
                time.sleep(1.0 / FPS)
            else:
                time.sleep(1.0 / FPS - lead_s)
                due = time.perf_counter() + lead_s
                detector.warm_up(previous, 'bgr8')
                time.sleep(max(due - time.perf_counter(), 0.0))
            start = time.perf_counter()
            detector.detect(image, 'bgr8')
            result[key].append(time.perf_counter() - start)
    return result


def _observations(count: int) -> list:
    """Return ``count`` observations of the default rig: spiral laps, one after another."""
    cameras = default_rig()
    scenario = make_scenario('spiral')
    period_ns = round(1e9 / FPS)
    lap_ns = (int(scenario.duration_s * 1e9) // period_ns + 1) * period_ns
    observations = []
    lap = 0
    while len(observations) < count:
        epoch_ns = DEFAULT_EPOCH_NS + lap * lap_ns
        stamps = [shutter_stamps(FPS, scenario.duration_s, phase_s=i / (2 * FPS),
                                 epoch_ns=epoch_ns) for i in range(len(cameras))]
        observations.extend(observe(scenario, cameras, stamps, epoch_ns=epoch_ns, seed=lap))
        lap += 1
    return observations[:count]


def bench_fuser_node(count: int) -> dict:
    """
    Time the fuser node, point received -> published, and the core fuser on the same points.

    :param count: image points
    :return: durations [s]: ``node`` (the node's own receive-to-publish times) and
        ``baseline`` (``Fuser.update`` of a copy of the node's core fuser, same observations)
    """
    observations = _observations(count)
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    namespace = f'bench_fuser_{os.getpid()}'
    rclpy.logging.set_logger_level(f'{namespace}.fuser', LoggingSeverity.WARN)
    baseline = []
    nodes = []
    try:
        fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('reorder_window_s', value=0.0),
            Parameter('diagnostics_period_s', value=0.0)])
        nodes.append(fuser)
        core = copy.deepcopy(fuser.fuser)  # same cameras and options, no state yet
        source = rclpy.create_node('bench_source', context=context, namespace=namespace)
        nodes.append(source)
        publishers = {name: source.create_publisher(PointStamped, f'{name}/ball/image_point',
                                                    100)
                      for name in sorted({o.camera for o in observations})}
        received = []
        sink = source.create_subscription(PointStamped, 'ball/position', received.append, 100)
        executor = make_executor(DEFAULT_EXECUTOR, context=context)
        executor.add_node(fuser)
        executor.add_node(source)
        for count_so_far, observation in enumerate(observations, 1):
            start = time.perf_counter()
            core.update(observation)
            baseline.append(time.perf_counter() - start)
            publishers[observation.camera].publish(observation_to_point(observation))
            spin([], executor=executor, context=context, duration_s=1.0, period_s=0.01,
                 until=lambda n=count_so_far: fuser.fuser.stats['observations'] >= n)
        spin([], executor=executor, context=context, duration_s=0.05)
        del sink
        times = list(fuser.processing_times_s)
        executor.shutdown()
        nodes = [fuser, source]
    finally:
        close(nodes, context=context)
    return {'node': times, 'baseline': baseline}


def transport_probe_main(argv: Optional[List[str]] = None) -> int:
    """
    Run the bare image subscriber of the transport baseline until SIGINT.

    Subscribes ``<namespace>/<camera>/image_raw`` as the detector does
    (``qos_profile_sensor_data``) and does nothing with the images but note
    the wall-clock time of arrival.  On SIGINT it prints one line per image,
    ``<stamp ns> <received ns>``, on stdout.

    :param argv: the namespace, then the camera names; None for ``sys.argv[1:]``
    :return: exit status
    """
    namespace, *names = sys.argv[1:] if argv is None else argv
    arrivals = []

    def on_image(msg):
        arrivals.append((msg.header.stamp.sec, msg.header.stamp.nanosec, time.time_ns()))

    rclpy.init(args=[])
    node = None
    try:
        node = rclpy.create_node('bench_transport_probe', namespace=namespace)
        for name in names:
            node.create_subscription(Image, f'{name}/image_raw', on_image,
                                     qos_profile_sensor_data)
        spin([node])
    finally:
        close([node])
    sys.stdout.write(''.join(f'{sec * 1_000_000_000 + nanosec} {received}\n'
                             for sec, nanosec, received in arrivals))
    return 0


def _start_transport_probe(namespace: str, names: Sequence[str]) -> subprocess.Popen:
    code = ('import sys\n'
            'from pseudo_stereo_ros.ros.bench_pipeline import transport_probe_main\n'
            'sys.exit(transport_probe_main())\n')
    return start_python(code, [namespace, *names], stdout=subprocess.PIPE, text=True)


def _stop_transport_probe(process: subprocess.Popen) -> List[Tuple[int, int]]:
    """Stop the probe; return its (stamp ns, received ns) pairs (empty when it failed)."""
    output = stop_processes([process])[0][0] or ''
    pairs = []
    for line in output.splitlines():
        try:
            stamp, received = (int(x) for x in line.split())
        except ValueError:
            continue
        pairs.append((stamp, received))
    return pairs


def _latencies(pairs, since_ns: Optional[int]) -> List[float]:
    """Return received - stamp [s] of the (stamp, received) [ns] pairs stamped at or after."""
    if since_ns is None:
        return []
    return [(received - stamp) / 1e9 for stamp, received in pairs if stamp >= since_ns]


def bench_end_to_end(seconds: float, *, connect_timeout_s: float = CONNECT_TIMEOUT_S) -> dict:
    """
    Time image stamp -> /ball/position with separate node processes, and the transport.

    Images stream at 2 x 30 Hz from the moment every process shows in the
    graph; the measurement starts with the first image after the first
    position came back.  Showing in this process's graph does not mean that
    the detector and fuser processes have matched each other's reliable
    endpoints: Fast DDS matches them up to a few seconds later, and points
    published before that never reach the fuser.

    :param seconds: measured streaming time [s]
    :param connect_timeout_s: longest wait for the processes to show and for the first
        position [s]
    :return: latencies [s]: ``pipeline`` (image stamp -> /ball/position received here) and
        ``transport`` (image stamp -> the same images received by a bare subscriber in
        another process); both only for images published after the warm-up; ``positions``
        (every position received, the warm-up's included) and ``fuser_report`` (the fuser
        process's last /diagnostics: input rates, estimates, drops; None before one came)
    """
    cameras, renderers = _renderers()
    points = _frame_points(200)
    names = [c.name for c in cameras]
    namespace = f'bench_e2e_{os.getpid()}'
    positions = []
    report = []  # the fuser process's last /diagnostics (for a run that gets no position)
    since_ns = None
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / 'params.yaml'
        params.write_text('/**/fuser:\n  ros__parameters:\n    reorder_window_s: 0.0\n')
        processes = [start_script('detector', ['--ros-args', '-r', f'__ns:=/{namespace}/{name}',
                                               '--log-level', 'warn']) for name in names]
        processes.append(start_script('fuser', [
            '--ros-args', '-r', f'__ns:=/{namespace}', '--params-file', str(params),
            '--log-level', 'warn']))
        probe = _start_transport_probe(f'/{namespace}', names)
        transport_pairs = []
        context = rclpy.Context()
        rclpy.init(args=[], context=context)
        node = None
        try:
            node = rclpy.create_node('bench_e2e', namespace=namespace, context=context)
            publishers = [node.create_publisher(Image, f'{name}/image_raw',
                                                qos_profile_sensor_data) for name in names]

            def on_position(msg):
                positions.append((stamp_to_ns(msg.header.stamp), time.time_ns()))

            node.create_subscription(PointStamped, 'ball/position', on_position, 100)

            def on_diagnostics(msg):
                for status in msg.status:
                    if status.name.startswith('fuser: '):
                        report[:] = [f'{status.message}; ' + ', '.join(
                            f'{v.key} {v.value}' for v in status.values
                            if 'input rate' in v.key or v.key.startswith(('estimates',
                                                                          'dropped')))]

            node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
            executor = make_executor(DEFAULT_EXECUTOR, context=context)
            executor.add_node(node)
            deadline = time.monotonic() + connect_timeout_s
            # Each image topic has two subscribers: the detector and the transport probe.
            spin([], executor=executor, context=context, duration_s=connect_timeout_s,
                 until=lambda: (all(p.get_subscription_count() >= 2 for p in publishers)
                                and node.count_publishers(f'/{namespace}/ball/position')))
            period = 1.0 / (FPS * len(cameras))
            start = time.monotonic()
            index = 0
            end_index = None
            while end_index is None or index < end_index:
                if end_index is None and positions:  # connected: measure from the next image
                    end_index = index + max(round(seconds / period), 1)
                elif end_index is None and time.monotonic() > deadline:
                    break
                camera = index % len(cameras)
                image = renderers[camera].render(points[index // len(cameras) % len(points)])
                msg = array_to_image(image, 'bgr8', 0, names[camera])
                spin([], executor=executor, context=context,
                     duration_s=start + index * period - time.monotonic())
                stamp_ns = time.time_ns()
                if end_index is not None and since_ns is None:
                    since_ns = stamp_ns
                msg.header.stamp = ns_to_stamp(stamp_ns)
                publishers[camera].publish(msg)
                index += 1
            spin([], executor=executor, context=context, duration_s=0.3)
            executor.shutdown()
        finally:
            close([node], context=context)
            transport_pairs = _stop_transport_probe(probe)
            stop_processes(processes, signal_number=signal.SIGTERM)
    return {'pipeline': _latencies(positions, since_ns),
            'transport': _latencies(transport_pairs, since_ns),
            'positions': len(positions), 'fuser_report': report[0] if report else None}


# -- camera_detector: capture and detection in one process ----------------------------------------

def hop_probe_main(argv: Optional[List[str]] = None) -> int:
    """
    Publish bare PointStamped messages stamped at publication until SIGINT (a baseline).

    :param argv: the topic and the rate [Hz]; None for ``sys.argv[1:]``
    :return: exit status
    """
    topic, rate = sys.argv[1:] if argv is None else argv
    rclpy.init(args=[])
    node = None
    try:
        node = rclpy.create_node('bench_hop_probe')
        publisher = node.create_publisher(PointStamped, topic, 10)

        def tick():
            msg = PointStamped()
            msg.header.stamp = ns_to_stamp(time.time_ns())
            publisher.publish(msg)

        node.create_timer(1.0 / float(rate), tick)
        spin([node])
    finally:
        close([node])
    return 0


def bench_camera_detectors(seconds: float, *, warm_up_s: Optional[float] = None) -> dict:
    """
    Time two ``camera_detector`` processes (virtual source) feeding a fuser in this process.

    Each camera_detector runs as its own process (virtual cameras, 30 fps, the
    second 1/60 s later; detection with the 48 px search window) and reports
    its own shutter -> frame available and frame available -> image point
    times on ``/diagnostics``.  The fuser node runs alone in this process's
    executor; its image point subscriptions and its ``/ball/position``
    publisher are wrapped (through the node's public ``subscriptions`` and
    ``publishers``) to note when a point's callback starts and when its
    position is published.  Baseline: a bare PointStamped hop from a third
    process publishing at 60 Hz, stamped at publication, received by a
    subscription in the same executor.

    :param seconds: measured time after the processes are connected [s]
    :param warm_up_s: the camera_detectors' ``warm_up_s`` (0: none, the detector cold as
        without a prediction of the next frame); None for the node's default
    :return: ``points`` (shutter stamp -> the fuser's callback starts [s]), ``positions``
        (shutter stamp -> ``/ball/position`` published [s]), ``hop`` (bare hop [s]),
        ``fuser`` (the fuser node's receive -> publish [s]) and ``diagnostics`` (camera name
        -> the camera_detector's last diagnostic values)
    """
    names = ['camera1', 'camera2']
    namespace = f'bench_cd_{os.getpid()}'
    # Past the processes' start-up (the cameras' own times include every frame): no frame is
    # late for its shutter because a process was still starting.
    epoch_ns = time.time_ns() + 3_000_000_000
    processes = [start_script('camera_detector', [
        '--ros-args', '-r', f'__ns:=/{namespace}/{name}', '-p', 'source:=virtual',
        '-p', f'calibration_file:={_rig_file(name)}', '-p', 'fps:=30.0',
        '-p', f'phase_s:={index / 60.0}', '-p', f'epoch_ns:={epoch_ns}', '-p', f'seed:={index}',
        '-p', 'ground_truth_topic:=ball/ground_truth', '-p', 'diagnostics_period_s:=0.5']
        + ([] if warm_up_s is None else ['-p', f'warm_up_s:={float(warm_up_s)}'])
        + ['--log-level', 'warn']) for index, name in enumerate(names)]
    code = ('import sys\n'
            'from pseudo_stereo_ros.ros.bench_pipeline import hop_probe_main\n'
            'sys.exit(hop_probe_main())\n')
    hop_topic = f'/{namespace}/hop'
    processes.append(start_python(code, [hop_topic, '60']))
    arrivals = {'points': [], 'positions': [], 'hop': []}
    heard = set()  # the cameras whose points reached the fuser's callback
    diagnostics = {}
    since_ns = None
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    rclpy.logging.set_logger_level(f'{namespace}.fuser', LoggingSeverity.WARN)
    fuser = probe = None
    try:
        fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('reorder_window_s', value=0.0), Parameter('diagnostics_period_s',
                                                                value=0.0)])

        def timed_callback(callback, topic):
            def wrapper(msg):
                arrivals['points'].append((decode_point(msg)[0], time.time_ns()))
                heard.add(topic)
                return callback(msg)
            return wrapper

        def timed_publish(publish):
            def wrapper(msg):
                publish(msg)
                published_ns = time.time_ns()
                # The fuser publishes serialized points (messages.point_encoder).
                stamp_ns = (decode_point(msg)[0] if isinstance(msg, bytes)
                            else stamp_to_ns(msg.header.stamp))
                arrivals['positions'].append((stamp_ns, published_ns))
            return wrapper

        for subscription in fuser.subscriptions:
            if subscription.topic_name.endswith('/ball/image_point'):
                subscription.callback = timed_callback(subscription.callback,
                                                       subscription.topic_name)
        for publisher in fuser.publishers:
            if publisher.topic_name.endswith('/ball/position'):
                publisher.publish = timed_publish(publisher.publish)
        probe = rclpy.create_node('bench_cd_probe', namespace=namespace, context=context)

        def on_hop(msg):
            arrivals['hop'].append((stamp_to_ns(msg.header.stamp), time.time_ns()))

        def on_diagnostics(msg):
            for status in msg.status:
                for name in names:
                    if status.name == f'camera_detector: {name}' and \
                            status.hardware_id.startswith('virtual'):
                        diagnostics[name] = {v.key: v.value for v in status.values}

        probe.create_subscription(PointStamped, hop_topic, on_hop, 100)
        probe.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        executor = make_executor(DEFAULT_EXECUTOR, context=context)
        # Connected when every camera's points reach the fuser and the hop arrives: DDS matches
        # the reliable endpoints up to a few seconds after they show in the graph.
        spin([fuser, probe], executor=executor, context=context, duration_s=CONNECT_TIMEOUT_S,
             until=lambda: len(heard) == len(names) and arrivals['hop'])
        since_ns = max(time.time_ns(), epoch_ns)
        spin([fuser, probe], executor=executor, context=context,
             duration_s=(since_ns - time.time_ns()) / 1e9 + seconds)
        executor.shutdown(timeout_sec=1.0)
        fuser_times = list(fuser.processing_times_s)
    finally:
        close([fuser, probe], context=context)
        stop_processes(processes)
    result = {key: _latencies(pairs, since_ns) for key, pairs in arrivals.items()}
    result['fuser'] = fuser_times
    result['diagnostics'] = diagnostics
    return result


def _rig_file(name: str) -> str:
    return str(config_dir() / 'rig' / f'{name}.yaml')


def _diagnostic_row(label: str, values: dict, key: str, *, target_ms: Optional[float] = None,
                    count_key: str = 'frames') -> str:
    """Return a table row from a camera_detector's reported percentiles [ms]."""
    try:
        n = int(values[count_key])
        median, p90 = float(values[f'{key} p50 [ms]']), float(values[f'{key} p90 [ms]'])
        p99 = float(values[f'{key} p99 [ms]'])
    except (KeyError, ValueError):
        return f'  {label:<{_LABEL_WIDTH}s}  no diagnostics received'
    target = ''
    if target_ms is not None:
        target = f'<= {target_ms:g} ' + ('ok' if median <= target_ms else 'OVER')
    return (f'  {label:<{_LABEL_WIDTH}s}{n:>6d}{median:>9.3f}{p90:>9.3f}  {target:<13s}'
            f'{"":>8s}  p99 {p99:.3f}').rstrip()


def print_camera_detector_rows(seconds: float, *, warm_up_s: Optional[float] = None) -> int:
    """
    Run :func:`bench_camera_detectors` and print its rows and where the time goes.

    :param seconds: measured time [s]
    :param warm_up_s: the camera_detectors' ``warm_up_s``; None for the node's default
    :return: exit status: 1 when nothing arrived
    """
    result = bench_camera_detectors(seconds, warm_up_s=warm_up_s)
    positions, points, hop = result['positions'], result['points'], result['hop']
    print('camera_detector processes (virtual source, 2 x 30 fps) -> fuser; shutter stamps'
          + ('' if warm_up_s is None else f'; warm_up_s {warm_up_s:g}') + ':')
    for name, values in sorted(result['diagnostics'].items()):
        print(_diagnostic_row(f'{name}: shutter -> frame available', values,
                              'shutter -> frame available'))
        print(_diagnostic_row(f'{name}: frame available -> point, 48 px', values,
                              'frame available -> image point',
                              target_ms=TARGETS_MS['camera_detector'],
                              count_key='timing samples'))
    print(_row('shutter -> image point in the fuser callback', points))
    p99 = f'  p99 {np.percentile(np.array(positions) * 1e3, 99):.3f}' if positions else ''
    ok99 = bool(positions) and np.percentile(np.array(positions) * 1e3, 99) <= \
        TARGETS_MS['shutter_to_position_p99']
    print(_row('shutter -> /ball/position published', positions,
               target_ms=TARGETS_MS['shutter_to_position'], baseline=hop if hop else None,
               extra=p99 + (f' (<= {TARGETS_MS["shutter_to_position_p99"]:g} '
                            f'{"ok" if ok99 else "OVER"})' if positions else '')))
    print(_row('  baseline: bare PointStamped hop', hop))
    wake = [float(v.get('shutter -> frame available p50 [ms]', 'nan'))
            for v in result['diagnostics'].values()]
    detect = [float(v.get('frame available -> image point p50 [ms]', 'nan'))
              for v in result['diagnostics'].values()]
    if positions and points and wake and detect:
        wake_ms, detect_ms = float(np.mean(wake)), float(np.mean(detect))
        point_ms, position_ms = _stats(points)[0], _stats(positions)[0]
        print('where the time goes (medians, ms; they add up only roughly):')
        for label, value in (
                ('shutter -> frame available (capture thread wakes)', wake_ms),
                ('detection + publish of the image point', detect_ms),
                ("DDS hop to the fuser's callback (bare hop median "
                 f'{_stats(hop)[0]:.3f})', point_ms - wake_ms - detect_ms),
                ('fuser: point received -> position published', position_ms - point_ms),
                ('total shutter -> /ball/position published', position_ms)):
            print(f'  {label:<60s}{value:8.3f}')
    if not positions:
        print('  camera_detector: no /ball/position published (DDS discovery failed?)')
        return 1
    return 0


def _load_rows(seconds: float, executor: str, soak: bool) -> Tuple[List[str], int]:
    """Run the 2 x 1,000 Hz load against the bare relay and the fuser; return rows, status."""
    relay = bench_load(min(seconds, 10.0) if soak else seconds, target='relay',
                       executor=executor)
    fuser = bench_load(seconds, target='fuser', executor=executor,
                       report_every_s=60.0 if soak else None)
    rows = []
    status = 0
    for result, label in ((fuser, f'fuser node, 2 x {LOAD_RATE_HZ:,.0f} Hz, stamp -> received'),
                          (relay, '  baseline: bare relay, same rate and core')):
        latencies = result['latencies_s']
        p99 = float(np.percentile(latencies, 99)) * 1e3 if latencies else float('nan')
        early, late = rss_growth(result['rss_kb'])
        lost_in = result['sent'] - result['taken']
        lost_out = (result['outputs'] - result['received']) if result['outputs'] is not None \
            else float('nan')
        extra = (f'  p99 {p99:.2f} max {max(latencies, default=float("nan")) * 1e3:.1f} ms; '
                 f'lost {lost_in} of {result["sent"]} in, {lost_out} out; '
                 f'CPU {result["cpu_fraction"]:.0%} of a core; '
                 f'RSS {early / 1024:.1f} -> {late / 1024:.1f} MiB')
        if result is fuser:
            if result['work_p99_ms'] is not None:
                extra += (f'; in the node: point received -> published p50 '
                          f'{result["work_p50_ms"]:.3f}, p99 {result["work_p99_ms"]:.2f} ms '
                          '(worst second)')
            rows.append(_row(label, latencies, target_p99_ms=TARGET_P99_MS,
                             baseline=relay['latencies_s'], extra=extra))
        else:
            rows.append(_row(label, latencies, extra=extra))
        if not latencies:
            rows.append(f'  {label.strip()}: nothing received (DDS discovery failed?)')
            status = 1
    late = fuser['source_late_p99_ms']
    rows.append(f'  (executor {executor}; {seconds:g} s; the lateness of the source itself, '
                f'p99 {late:.2f} ms, is part of both rows: mostly back-pressure from the target)')
    return rows, status


def main(argv: Optional[List[str]] = None) -> int:
    """Run the benchmarks and print the table; return the exit status."""
    parser = argparse.ArgumentParser(prog='bench_pipeline', description=__doc__.split('\n')[1])
    parser.add_argument('--frames', type=int, default=None,
                        help=f'frames for the detector (default {FULL_RUN["frames"]})')
    parser.add_argument('--points', type=int, default=None,
                        help=f'image points for the fuser (default {FULL_RUN["points"]})')
    parser.add_argument('--seconds', type=float, default=None,
                        help=f'end-to-end run time [s] (default {FULL_RUN["seconds"]:g})')
    parser.add_argument('--load-seconds', type=float, default=None,
                        help=f'2 x {LOAD_RATE_HZ:,.0f} Hz load run time [s] (default '
                        f'{FULL_RUN["load_seconds"]:g})')
    parser.add_argument('--executor', choices=EXECUTORS, default=DEFAULT_EXECUTOR,
                        help=f'executor of the fuser and the relay under load (default '
                        f'{DEFAULT_EXECUTOR})')
    parser.add_argument('--soak', type=float, nargs='?', const=600.0, default=None,
                        metavar='SECONDS',
                        help='only the load row, for SECONDS (default 600), with the '
                        "fuser's resident memory every minute")
    parser.add_argument('--quick', action='store_true',
                        help='a short run that only checks the benchmark works: ' +
                        ', '.join(f'{k} {v:g}' for k, v in QUICK_RUN.items()))
    parser.add_argument('--skip-end-to-end', action='store_true',
                        help='no separate processes (no DDS discovery needed; no load row)')
    parser.add_argument('--latency-only', action='store_true',
                        help='only the camera_detector processes -> fuser block (--seconds)')
    parser.add_argument('--warm-up-s', type=float, default=None,
                        help="the camera_detectors' warm_up_s (0: cold, as a camera whose "
                        "next frame is not predicted); default the node's")
    options = parser.parse_args(argv)
    sizes = QUICK_RUN if options.quick else FULL_RUN
    for key, value in sizes.items():
        if getattr(options, key) is None:
            setattr(options, key, value)
        if not getattr(options, key) > 0:
            parser.error(f'--{key.replace("_", "-")} must be positive')
    if options.soak is not None and not options.soak > 0:
        parser.error('--soak must be positive')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    # Before any DDS participant exists: 900 kB frames need a larger shared-memory segment.
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          str(config_dir() / 'fastdds_large_images.xml'))
    print('bench_pipeline: 640x480 frames, default rig, spiral; times in ms per frame or event;')
    print('ratio = median / median of the baseline row below it (same inputs, same run)')
    print(_header())
    if options.soak is not None:
        rows, status = _load_rows(options.soak, options.executor, soak=True)
        print('\n'.join(rows))
        return status
    if options.latency_only:
        return print_camera_detector_rows(options.seconds, warm_up_s=options.warm_up_s)
    detector = bench_detector(options.frames)
    print(_row('detector, full frame', detector['full'], target_ms=TARGETS_MS['full'],
               baseline=detector['baseline']))
    print(_row('detector, search window 48 px', detector['window'],
               target_ms=TARGETS_MS['window'], baseline=detector['baseline']))
    print(_row('  baseline: cv2.cvtColor BGR->HSV, full frame', detector['baseline']))
    # Ratios to the back-to-back 48 px row above: what a frame period of sleep costs.
    print(_row('detector, 48 px, one per frame period (cold)', detector['cold'],
               baseline=detector['window'], extra='  (ratio to the 48 px row)'))
    print(_row('detector, 48 px, warmed up 2 ms before', detector['warmed'],
               baseline=detector['window'], extra='  (ratio to the 48 px row)'))
    sys.stdout.flush()
    fuser = bench_fuser_node(options.points)
    print(_row('fuser node, point received -> published', fuser['node'],
               target_ms=TARGETS_MS['fuser'], baseline=fuser['baseline']))
    print(_row('  baseline: core Fuser.update, same points', fuser['baseline']))
    sys.stdout.flush()
    status = 0
    if not options.skip_end_to_end:
        latencies = bench_end_to_end(options.seconds)
        pipeline, transport = latencies['pipeline'], latencies['transport']
        extra = ''
        if pipeline and transport:
            extra = f'  (+{_stats(pipeline)[0] - _stats(transport)[0]:.3f} ms)'
        print(_row('end to end, image stamp -> /ball/position', pipeline,
                   target_ms=TARGETS_MS['end_to_end'],
                   baseline=transport if transport else None, extra=extra))
        print(_row('  baseline: image stamp -> bare subscriber', transport))
        if not pipeline:
            print(f'  end to end: no /ball/position received while measuring (DDS discovery '
                  f'failed?); {latencies["positions"]} before; the fuser last reported: '
                  f'{latencies["fuser_report"] or "nothing"}')
            status = 1
        if not transport:
            print('  transport baseline: no image received by the probe process')
            status = 1
        sys.stdout.flush()
        status = max(status, print_camera_detector_rows(options.seconds,
                                                        warm_up_s=options.warm_up_s))
        rows, load_status = _load_rows(options.load_seconds, options.executor, soak=False)
        print('\n'.join(rows))
        status = max(status, load_status)
    print(f'paper (other hardware): image analysis {PAPER_IMAGE_ANALYSIS_MS} ms, '
          f'capture to 3D {PAPER_CAPTURE_TO_3D_MS} ms; (+x ms): median minus baseline median')
    return status


if __name__ == '__main__':
    sys.exit(main())
