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
``bench_pipeline``: how fast the live pipeline is, beside the paper's figures.

Prints, as median and 90th percentile:

1. the detector core per 640x480 frame, full frame and with the search window
   (paper: 2.6 ms image analysis);
2. the fuser node from receiving an image point to publishing its estimate
   (in-process, reorder window 0, the default);
3. end to end on loopback, image stamp to ``/ball/position``: the
   ``detector`` (one per camera) and ``fuser`` console scripts run as
   separate processes; this process publishes rendered images stamped with
   the wall clock at publication and receives the positions (paper: 4.13 ms
   from capture to 3D).

Numbers depend on the machine and its load; compare the ratios.
"""

import argparse
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time
from typing import List, Optional

import numpy as np

__all__ = ['main']

PAPER_IMAGE_ANALYSIS_MS = 2.6
PAPER_CAPTURE_TO_3D_MS = 4.13
TARGETS_MS = {'window': 1.0, 'full': 3.0, 'fuser': 0.5, 'end_to_end': 5.0}


def _stats(seconds) -> tuple:
    ms = np.asarray(seconds, dtype=float) * 1e3
    return float(np.median(ms)), float(np.percentile(ms, 90))


def _line(label: str, values: tuple, target: float, paper: str) -> str:
    median, p90 = values
    verdict = 'ok' if median <= target else 'OVER'
    return (f'  {label:<44s} median {median:7.3f} ms  p90 {p90:7.3f} ms  '
            f'(target <= {target:g} ms: {verdict}; {paper})')


def _frames(count: int):
    from .rendering import BallRenderer
    from .simulation import default_rig, make_scenario, shutter_stamps, truth_at
    cameras = default_rig()
    scenario = make_scenario('spiral')
    stamps = shutter_stamps(30.0, scenario.duration_s)[:count]
    points = truth_at(scenario, stamps)
    return cameras, points, [BallRenderer(camera, noise_std=2.0, seed=i)
                             for i, camera in enumerate(cameras)]


def bench_detector(count: int) -> dict:
    """Return detector timings [s] per frame: ``full`` and ``window``."""
    from .detection import BallDetector
    _, points, renderers = _frames(count)
    images = [renderers[0].render(p) for p in points]
    result = {}
    for key, window in (('full', 0), ('window', 48)):
        detector = BallDetector(search_window_px=window)
        detector.detect(images[0], 'bgr8')  # warm caches
        times = []
        for image in images:
            start = time.perf_counter()
            detector.detect(image, 'bgr8')
            times.append(time.perf_counter() - start)
        result[key] = times
    return result


def bench_fuser_node(count: int) -> list:
    """Return the fuser node's receive-to-publish times [s] for ``count`` image points."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from geometry_msgs.msg import PointStamped
    from .fuser_node import FuserNode
    from .messages import observation_to_point
    from .simulation import default_rig, make_scenario, observe, shutter_stamps

    cameras = default_rig()
    scenario = make_scenario('spiral')
    stamps = [shutter_stamps(30.0, scenario.duration_s, phase_s=i / 60.0) for i in range(2)]
    observations = observe(scenario, cameras, stamps)[:count]
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    namespace = f'/bench_fuser_{os.getpid()}'
    try:
        fuser = FuserNode(context=context, namespace=namespace, parameter_overrides=[
            Parameter('reorder_window_s', value=0.0),
            Parameter('diagnostics_period_s', value=0.0)])
        source = rclpy.create_node('bench_source', context=context, namespace=namespace)
        publishers = {c.name: source.create_publisher(PointStamped, f'{c.name}/ball/image_point',
                                                      100) for c in cameras}
        received = []
        sink = source.create_subscription(PointStamped, 'ball/position', received.append, 100)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(fuser)
        executor.add_node(source)
        for observation in observations:
            publishers[observation.camera].publish(observation_to_point(observation))
            deadline = time.monotonic() + 1.0
            before = len(fuser.processing_times_s) + fuser.fuser.stats['observations']
            while (len(fuser.processing_times_s) + fuser.fuser.stats['observations'] == before
                   and time.monotonic() < deadline):
                executor.spin_once(timeout_sec=0.01)
        executor.spin_once(timeout_sec=0.05)
        del sink
        times = list(fuser.processing_times_s)
        executor.shutdown()
        fuser.destroy_node()
        source.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return times


def _script(name: str) -> str:
    candidate = Path(sys.executable).parent / name
    if candidate.exists():
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f'console script {name!r} not found beside {sys.executable} '
                                'or on PATH')
    return found


def bench_end_to_end(seconds: float) -> list:
    """Return image stamp -> /ball/position latencies [s] with separate node processes."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from geometry_msgs.msg import PointStamped
    from sensor_msgs.msg import Image
    from .messages import array_to_image, ns_to_stamp, stamp_to_ns

    cameras, points, renderers = _frames(10_000)
    namespace = f'bench_e2e_{os.getpid()}'
    with tempfile.TemporaryDirectory() as tmp:
        params = Path(tmp) / 'params.yaml'
        params.write_text('/**/fuser:\n  ros__parameters:\n    reorder_window_s: 0.0\n')
        processes = [subprocess.Popen(
            [_script('detector'), '--ros-args', '-r', f'__ns:=/{namespace}/{c.name}',
             '--log-level', 'warn'], stdin=subprocess.DEVNULL) for c in cameras]
        processes.append(subprocess.Popen(
            [_script('fuser'), '--ros-args', '-r', f'__ns:=/{namespace}', '--params-file',
             str(params), '--log-level', 'warn'], stdin=subprocess.DEVNULL))
        context = rclpy.Context()
        rclpy.init(args=[], context=context)
        latencies = []
        try:
            node = rclpy.create_node('bench_e2e', namespace=namespace, context=context)
            publishers = [node.create_publisher(Image, f'{c.name}/image_raw',
                                                qos_profile_sensor_data) for c in cameras]

            def on_position(msg):
                latencies.append((time.time_ns() - stamp_to_ns(msg.header.stamp)) / 1e9)

            node.create_subscription(PointStamped, 'ball/position', on_position, 100)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            deadline = time.monotonic() + 30.0
            while time.monotonic() < deadline and not (
                    all(p.get_subscription_count() for p in publishers)
                    and node.count_publishers(f'/{namespace}/ball/position')):
                executor.spin_once(timeout_sec=0.05)
            time.sleep(0.5)  # let the reliable point topics match too
            period = 1.0 / 60.0
            start = time.monotonic()
            index = 0
            warm_up = 20
            while time.monotonic() - start < seconds + warm_up * period:
                camera = index % 2
                frame = index // 2 % len(points)
                image = renderers[camera].render(points[frame])
                msg = array_to_image(image, 'bgr8', 0, cameras[camera].name)
                next_time = start + index * period
                while time.monotonic() < next_time:
                    executor.spin_once(timeout_sec=max(next_time - time.monotonic(), 0))
                if index == warm_up:
                    latencies.clear()
                msg.header.stamp = ns_to_stamp(time.time_ns())
                publishers[camera].publish(msg)
                index += 1
            end = time.monotonic() + 0.3
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            executor.shutdown()
            node.destroy_node()
        finally:
            rclpy.try_shutdown(context=context)
            for process in processes:
                process.terminate()
            for process in processes:
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    process.kill()
    return latencies


def main(argv: Optional[List[str]] = None) -> int:
    """Run the benchmarks and print the table; return the exit status."""
    parser = argparse.ArgumentParser(prog='bench_pipeline', description=__doc__.split('\n')[1])
    parser.add_argument('--frames', type=int, default=88, help='frames for the detector')
    parser.add_argument('--points', type=int, default=300, help='image points for the fuser')
    parser.add_argument('--seconds', type=float, default=5.0, help='end-to-end run time [s]')
    parser.add_argument('--skip-end-to-end', action='store_true',
                        help='no separate processes (no DDS discovery needed)')
    options = parser.parse_args(argv)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    # Before any DDS participant exists: 900 kB frames need a larger shared-memory segment.
    from .simulation import config_dir
    os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE',
                          str(config_dir() / 'fastdds_large_images.xml'))
    print('bench_pipeline (640x480 frames, default rig, spiral; times per frame or event)')
    detector = bench_detector(options.frames)
    paper = f'paper: image analysis {PAPER_IMAGE_ANALYSIS_MS} ms'
    print(_line('detector, full frame', _stats(detector['full']), TARGETS_MS['full'], paper))
    print(_line('detector, search window 48 px', _stats(detector['window']),
                TARGETS_MS['window'], paper))
    fuser = bench_fuser_node(options.points)
    print(_line(f'fuser node, point received -> published (n={len(fuser)})', _stats(fuser),
                TARGETS_MS['fuser'], 'paper: no figure'))
    if not options.skip_end_to_end:
        latencies = bench_end_to_end(options.seconds)
        if latencies:
            print(_line(f'end to end, image stamp -> /ball/position (n={len(latencies)})',
                        _stats(latencies), TARGETS_MS['end_to_end'],
                        f'paper: capture to 3D {PAPER_CAPTURE_TO_3D_MS} ms'))
        else:
            print('  end to end: no /ball/position received (DDS discovery failed?)')
            return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
