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
Multi-process tests over DDS on loopback: the console scripts as separate processes.

The detector and fuser run as their own processes with a params file; this
process publishes rendered images, records the detectors' image points and
checks that ``/ball/position`` carries one message per shutter event, with
the events' stamps and the positions the core ``fuse()`` (the code path of
``pseudo_stereo track``) computes from the same image points.

No sleeps synchronize: warm-up flights run until the fuser publishes a
position (so both detector -> fuser connections are matched, and reliable
from then on), and each image is followed by waiting for its image point.
Every process showing in this process's graph is not enough: Fast DDS
matches the detector and fuser processes' reliable endpoints with each other
up to seconds later (up to 2.1 s in six instrumented runs, longer in the
failing ones), and one fixed warm-up flight played as fast as the
detectors answer (about 2.5 s on a quiet machine) sometimes ended first.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import time

from geometry_msgs.msg import PointStamped
import numpy as np
from pseudo_stereo_ros.fusion import fuse
from pseudo_stereo_ros.ros.messages import array_to_image, point_to_observation, point_to_xyz
from pseudo_stereo_ros.ros.processes import start_script, stop_processes
from pseudo_stereo_ros.sim.rendering import BallRenderer
from pseudo_stereo_ros.sim.scenarios import (DEFAULT_EPOCH_NS, default_rig, make_scenario,
                                             shutter_stamps, truth_at)
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Image

BIN = Path(sys.executable).parent
# Frames of 900 kB do not fit Fast DDS's default shared-memory segment (see the profile). Set at
# import, before any test of the session creates a DDS participant; child processes inherit it.
os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(
    Path(__file__).resolve().parent.parent / 'config' / 'fastdds_large_images.xml'))


def _start(args):
    return start_script(args[0], args[1:], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                        text=True)


def test_detector_and_fuser_processes(tmp_path):
    namespace = f'mp{os.getpid()}'
    params = tmp_path / 'params.yaml'
    # A reorder window far longer than a detector's lag under load: no point arrives late, so
    # the node's output must equal fuse() of the same points exactly.
    params.write_text('/**/fuser:\n  ros__parameters:\n    method: paper\n'
                      '    reorder_window_s: 0.2\n    max_gap_s: 0.5\n'
                      '/**/detector:\n  ros__parameters:\n    search_window_px: 48\n')
    cameras = default_rig()
    processes = [_start(['detector', '--ros-args', '-r', f'__ns:=/{namespace}/{c.name}',
                         '--params-file', str(params)]) for c in cameras]
    processes.append(_start(['fuser', '--ros-args', '-r', f'__ns:=/{namespace}',
                             '--params-file', str(params)]))
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    points, positions = [], []
    scenario = make_scenario('turntable')
    renderers = [BallRenderer(c, radius_m=0.03, noise_std=2.0, seed=i)
                 for i, c in enumerate(cameras)]

    def events(epoch_ns, duration_s):
        stamps = [shutter_stamps(30.0, duration_s, phase_s=i / 60.0, epoch_ns=epoch_ns)
                  for i in range(2)]
        return sorted((int(s), i) for i, camera_stamps in enumerate(stamps)
                      for s in camera_stamps)

    try:
        node = rclpy.create_node('probe', namespace=namespace, context=context)
        publishers = [node.create_publisher(Image, f'{c.name}/image_raw',
                                            qos_profile_sensor_data) for c in cameras]
        for camera in cameras:
            node.create_subscription(
                PointStamped, f'{camera.name}/ball/image_point',
                lambda msg, name=camera.name: points.append(point_to_observation(msg, name)), 100)
        node.create_subscription(PointStamped, 'ball/position',
                                 lambda msg: positions.append(point_to_xyz(msg)), 100)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)

        def spin_until(predicate, timeout_s):
            deadline = time.monotonic() + timeout_s
            while not predicate() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.02)
            return predicate()

        def play(stamp, index, epoch_ns):
            image = renderers[index].render(truth_at(scenario, [stamp], epoch_ns=epoch_ns)[0])
            publishers[index].publish(array_to_image(image, 'bgr8', stamp, cameras[index].name))
            # Wait for the detector's point (best-effort images may, rarely, be lost).
            return spin_until(lambda: any(p.stamp_ns == stamp for p in points[-2:]), 2.0)

        assert spin_until(lambda: all(p.get_subscription_count() for p in publishers)
                          and node.count_publishers(f'/{namespace}/ball/position')
                          and all(node.count_subscribers(f'/{namespace}/{c.name}/ball/image_point')
                                  >= 2 for c in cameras), 30.0), 'processes did not come up'
        # Warm-up flights, each 10 s before the previous one (far beyond max_gap: a fresh
        # start, and a jump both cameras agree on), until the fuser publishes a position.
        deadline = time.monotonic() + 60.0
        warm_epoch = DEFAULT_EPOCH_NS
        while not positions and time.monotonic() < deadline:
            warm_epoch -= 10_000_000_000
            for stamp, index in events(warm_epoch, 5.0):
                play(stamp, index, warm_epoch)
                if positions or time.monotonic() > deadline:
                    break
        assert positions, 'no position from the fuser process within 60 s of warm-up flights'
        start = len(points)
        played = events(DEFAULT_EPOCH_NS, 1.0)
        lost = sum(not play(stamp, index, DEFAULT_EPOCH_NS) for stamp, index in played)
        measured = points[start:]
        expected, _ = fuse(cameras, measured, max_gap_ns=500_000_000)
        assert spin_until(lambda: sum(p[0] >= DEFAULT_EPOCH_NS for p in positions)
                          >= len(expected), 10.0)
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        stop_processes(processes, signal_number=signal.SIGTERM)
    # Best-effort images on loopback: nearly every event is detected.
    assert lost <= 0.1 * len(played) and len(measured) >= 0.9 * len(played)
    assert len(expected) >= len(measured) - 3  # one estimate per event after warm-up
    measured_positions = [p for p in positions if p[0] >= DEFAULT_EPOCH_NS]
    assert [p[0] for p in measured_positions] == [e.stamp_ns for e in expected]
    np.testing.assert_allclose([p[1:] for p in measured_positions],
                               [(e.x, e.y, e.z) for e in expected], rtol=0, atol=1e-9)
    # And the estimates are where the ball was (detections of a 3 px ball: mm accuracy).
    truth = truth_at(scenario, [p[0] for p in measured_positions])
    errors = np.linalg.norm(np.array([p[1:] for p in measured_positions]) - truth, axis=1)
    assert np.median(errors) < 0.02


@pytest.mark.parametrize('args, name', [
    (['fuser', '--ros-args', '-p', 'camera_names:=[]'], 'camera_names'),
    (['fuser', '--ros-args', '-p', 'method:=kalman'], 'method'),
    (['fuser', '--ros-args', '-p', 'max_gap_s:=1'], 'max_gap_s'),
    (['detector', '--ros-args', '-p', 'choice:=brightest'], 'choice'),
    (['virtual_camera', '--ros-args', '-p', 'scenario:=loop'], 'scenario'),
])
def test_bad_parameter_stops_the_node_naming_it(args, name):
    result = subprocess.run([str(BIN / args[0])] + args[1:] + ['-r', f'__ns:=/bad{os.getpid()}'],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert name in result.stderr
    # Logged under the node's name in its namespace, as its other log lines.
    assert f'[bad{os.getpid()}.{args[0]}]: cannot start' in result.stderr


@pytest.mark.parametrize('program', ['fuser', 'detector', 'bringup'])
@pytest.mark.parametrize('problem', ['missing', 'malformed'])
def test_bad_params_file_stops_with_one_line(tmp_path, program, problem):
    path = tmp_path / 'params.yaml'
    if problem == 'malformed':
        path.write_text('/**/fuser:\n  ros__parameters:\n    method: [paper\n')
    args = ['--ros-args', '-r', f'__ns:=/bad{os.getpid()}', '--params-file', str(path)]
    if program == 'bringup':
        args = ['--params-file', str(path)]
    result = subprocess.run([str(BIN / program)] + args, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode in (1, 2)
    # One line: before, rcl's own "[ERROR] [rcl]: Failed to parse global arguments" came first.
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert str(path) in result.stderr and ('cannot start' in result.stderr
                                           or 'no such file' in result.stderr)


@pytest.mark.parametrize('args, reason', [
    (['fuser', '--ros-args', '-p', 'camera_names:=[cam-1, camera2]'],
     "parameter camera_names: camera name 'cam-1' is not a valid ROS name"),
    (['detector', '--ros-args', '-r', '__ns:=/22276213'], "Couldn't parse remap rule"),
    (['fuser', '--ros-args', '-p', 'method:=[paper'], "Couldn't parse parameter override"),
])
def test_bad_names_and_arguments_stop_the_node_with_one_line(args, reason):
    # Before: a 26-line InvalidTopicNameException; rcl's ERROR line before the FATAL one.
    result = subprocess.run([str(BIN / args[0])] + args[1:], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and '[FATAL]' in lines[0] and 'cannot start' in lines[0], lines
    assert reason in lines[0]


def test_malformed_calibration_file_stops_the_node_naming_it(tmp_path):
    bad = tmp_path / 'broken.yaml'
    bad.write_text('camera_name: camera2\nimage_width: 640\nimage_height: [480\n')
    result = subprocess.run(
        [str(BIN / 'fuser'), '--ros-args', '-r', f'__ns:=/bad{os.getpid()}', '-p',
         f'calibration_files:=[{bad}, {bad}]'], capture_output=True, text=True, timeout=60)
    assert result.returncode != 0
    assert 'broken.yaml' in result.stderr and 'not valid YAML' in result.stderr


def _descendants(pid):
    """Return the pids of every process below ``pid`` (from /proc)."""
    parents = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / 'stat').read_text()
            except OSError:
                continue
            parents.setdefault(int(stat.rpartition(')')[2].split()[1]), []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        children = parents.get(todo.pop(), [])
        found += children
        todo += children
    return found


def _running(pid):
    try:
        return Path(f'/proc/{pid}/stat').read_text().rpartition(')')[2].split()[0] != 'Z'
    except OSError:
        return False


@pytest.mark.skipif(not Path('/proc').is_dir(), reason='reads /proc')
def test_a_killed_fuser_leaves_no_helper_process():
    # The online time-offset estimate runs in a worker process (and multiprocessing's fork
    # server and resource tracker): SIGKILL of the node must not leave them running, even
    # while the dead node is not yet reaped (a zombie), and its pipes must close.
    fuser = start_script('fuser', ['--ros-args', '-r', f'__ns:=/killed{os.getpid()}'],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60.0
        helpers = []
        while len(helpers) < 3 and time.monotonic() < deadline and fuser.poll() is None:
            time.sleep(0.2)
            helpers = _descendants(fuser.pid)
        assert len(helpers) >= 3, f'the fuser started {len(helpers)} helper processes, not 3'
        os.kill(fuser.pid, signal.SIGKILL)  # not reaped: a zombie until communicate() ends
        deadline = time.monotonic() + 30.0
        while any(_running(pid) for pid in helpers) and time.monotonic() < deadline:
            time.sleep(0.2)
        left = [pid for pid in helpers if _running(pid)]
        for pid in left:
            os.kill(pid, signal.SIGKILL)
        assert not left, f'helper processes {left} outlived the killed fuser'
        fuser.communicate(timeout=30.0)  # the pipes closed: nothing holds them any more
    finally:
        if fuser.poll() is None:
            fuser.kill()
            fuser.communicate()
