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
The fuser node under load: 2 x 1,000 Hz image points, beside a bare relay at the same rate.

Three processes on loopback DDS:

* a **source** publishes ``camera1`` and ``camera2`` image points at
  ``rate_hz`` each (camera 2 half a period after camera 1: 2,000
  messages/s at 1 kHz), the turntable scenario seen by the default rig
  with 0.3 px noise.  Each point is stamped with the wall-clock time it is
  due and published then, so ``received - stamp`` at the end of the chain
  is the whole delay: the source's own lateness, two DDS hops and the
  node's queueing and work.  The source's lateness is printed on its own:
  it rises and falls with the target's stalls (back-pressure through the
  reliable topics: up to 265 ms at p99 while the fuser's offset estimate
  stalled it, 2-3 ms otherwise), so it belongs in the row;
* the **target**, pinned to one core (the last one): the ``fuser``
  console script with its defaults (``reorder_window_s`` 0, marker and
  diagnostics timers on), or, as the baseline, a **bare relay**: a node
  that subscribes the same topics with the same QoS and publishes every
  message unchanged on ``ball/position``, on the same executor;
* the **sink** (this process) receives ``ball/position`` and the fuser's
  ``/diagnostics`` and samples the target's resident memory every second.

Reported: receive -> publish latency (source stamp -> sink) p50 / p99 /
max after a 0.5 s warm-up; the fuser's own work per point (callback start
-> position published, from its ``/diagnostics``: the median of each
second's p50, the worst second's p99); inputs lost (sent minus what the target took:
the fuser's ``observations`` on ``/diagnostics``, the relay's outputs);
outputs lost (the fuser's ``estimates`` minus ``ball/position`` received);
resident memory of the target after 10% of the run and at its end.
"""

import os
import subprocess
import sys
import time
from typing import Dict, List, Optional, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.qos import HistoryPolicy, QoSProfile

from .fuser_node import INPUT_QUEUE_DEPTH
from .messages import decode_point, observation_to_point
from .node_tools import close, DEFAULT_EXECUTOR, make_executor, spin
from .processes import start_python, start_script, stop_processes
from ..records import Observation
from ..sim.scenarios import default_rig, make_scenario, shutter_stamps, truth_at

__all__ = ['bench_load', 'relay_main', 'rss_growth', 'source_main']

#: Image point rate per camera [Hz] of the load row, and its receive -> publish p99 target.
LOAD_RATE_HZ = 1000.0
TARGET_P99_MS = 2.0
WARM_UP_S = 0.5
_NS = 1_000_000_000


def _cpus():
    """Return (target cpu, the others) or (None, None) without a choice of cores."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return None, None
    if len(cpus) < 2:
        return None, None
    return cpus[-1], set(cpus[:-1])


def _cpu_s(pid: int) -> Optional[float]:
    """Return the CPU time [s] a process used so far (user + system)."""
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as stat:
            fields = stat.read().rsplit(')', 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')
    except (OSError, ValueError, IndexError):
        return None


def _rss_kb(pid: int) -> Optional[int]:
    try:
        with open(f'/proc/{pid}/status', encoding='ascii') as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1])
    except (OSError, ValueError):
        return None
    return None


# -- the source and the relay (child processes) ---------------------------------------------------

def source_main(argv: Optional[List[str]] = None) -> int:
    """
    Publish two cameras' image points at a fixed rate, each stamped with its due time.

    Arguments: namespace, rate [Hz], seconds.  Waits (up to 60 s) for a
    subscriber on both topics, then publishes; prints
    ``sent <count> <first stamp ns> <late p99 ms>`` on stdout at the end.

    :param argv: the arguments; None for ``sys.argv[1:]``
    :return: exit status
    """
    namespace, rate, seconds = (sys.argv[1:] if argv is None else argv)[:3]
    rate, seconds = float(rate), float(seconds)
    cameras = default_rig()
    scenario = make_scenario('turntable')
    rclpy.init(args=[])
    node = rclpy.create_node('bench_load_source', namespace=namespace)
    publishers = {c.name: node.create_publisher(PointStamped, f'{c.name}/ball/image_point', 10)
                  for c in cameras}
    # Every shutter of the run, computed before the first one (a pause for numpy in the middle
    # of the run would show as latency): stamps relative to the start, pixels, camera index.
    offsets, pixels, which = [], [], []
    rng = np.random.default_rng(0)
    for index, camera in enumerate(cameras):
        stamps = shutter_stamps(rate, seconds - 1e-9, phase_s=index / (2 * rate), epoch_ns=0)
        points = camera.project(truth_at(scenario, stamps, epoch_ns=0))
        points = np.round((points + rng.normal(0.0, 0.3, points.shape)) / 0.05) * 0.05
        offsets.append(stamps)
        pixels.append(points)
        which.append(np.full(len(stamps), index))
    offsets, pixels, which = (np.concatenate(x) for x in (offsets, pixels, which))
    order = np.argsort(offsets, kind='stable')
    offsets, pixels, which = offsets[order].tolist(), pixels[order].tolist(), which[order].tolist()
    topics = [publishers[camera.name] for camera in cameras]
    deadline = time.monotonic() + 60.0
    while (time.monotonic() < deadline
           and any(p.get_subscription_count() == 0 for p in publishers.values())):
        time.sleep(0.05)
    time.sleep(0.5)  # the reliable readers match a moment after they show in the graph
    epoch = (time.time_ns() // 1_000_000 + 100) * 1_000_000
    sent, lateness = 0, []
    try:
        for offset, (u, v), index in zip(offsets, pixels, which):
            stamp = epoch + offset
            message = observation_to_point(Observation(cameras[index].name, stamp, u, v),
                                           cameras[index].name)
            delay = (stamp - time.time_ns()) / _NS
            if delay > 0:
                time.sleep(delay)
            lateness.append(time.time_ns() - stamp)
            topics[index].publish(message)
            sent += 1
        for publisher in publishers.values():
            publisher.wait_for_all_acked(Duration(seconds=2.0))
    finally:
        late_p99 = float(np.percentile(lateness, 99)) / 1e6 if lateness else float('nan')
        sys.stdout.write(f'sent {sent} {epoch} {late_p99:.3f}\n')
        sys.stdout.flush()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def relay_main(argv: Optional[List[str]] = None) -> int:
    """
    Run the bare relay: image points in, the same messages out on ``ball/position``.

    Arguments: namespace, executor kind, then the camera names.  Same QoS
    as the fuser (subscriptions ``INPUT_QUEUE_DEPTH`` deep, publisher depth 10); runs until
    SIGINT.

    :param argv: the arguments; None for ``sys.argv[1:]``
    :return: exit status
    """
    namespace, executor, *names = sys.argv[1:] if argv is None else argv
    rclpy.init(args=[])
    node = rclpy.create_node('bench_relay', namespace=namespace)
    publisher = node.create_publisher(PointStamped, 'ball/position', 10)
    for name in names:
        # Raw bytes in and out: the barest relay (the fuser takes its points raw too).
        node.create_subscription(PointStamped, f'{name}/ball/image_point', publisher.publish,
                                 INPUT_QUEUE_DEPTH, raw=True)
    try:
        spin([node], executor=executor)
    finally:
        close([node])
    return 0


# -- the sink and the run -------------------------------------------------------------------------

def bench_load(seconds: float, *, target: str = 'fuser', rate_hz: float = LOAD_RATE_HZ,
               executor: str = DEFAULT_EXECUTOR, report_every_s: Optional[float] = None,
               parameters: Sequence[str] = ()) -> Dict[str, object]:
    """
    Run the source against the fuser node (or the bare relay) and measure it.

    :param seconds: how long the source publishes [s]
    :param target: ``'fuser'`` or ``'relay'``
    :param rate_hz: image points per camera per second
    :param executor: the target's executor kind
    :param report_every_s: print the target's resident memory this often (a soak); None: quiet
    :param parameters: more ``name:=value`` parameters of the fuser
    :return: ``latencies_s`` (after the warm-up), ``sent``, ``taken`` (inputs the target
        took), ``outputs`` (messages it published; None when unknown), ``received``,
        ``rss_kb`` [(seconds since start, kB)], ``source_late_p99_ms``, ``work_p50_ms`` and
        ``work_p99_ms`` (the fuser's own point received -> published: median of the seconds'
        p50, worst second's p99; None for the relay), ``cpu_fraction`` (CPU
        time of the target / wall time while the source ran; 1.0 = one core busy)
    """
    namespace = f'bench_load_{os.getpid()}_{target}'
    target_cpu, others = _cpus()
    names = [camera.name for camera in default_rig()]
    if target == 'fuser':
        process = start_script(
            'fuser', ['--executor', executor, '--ros-args', '-r', f'__ns:=/{namespace}', '-p',
                      'reorder_window_s:=0.0', '--log-level', 'warn',
                      *[arg for parameter in parameters for arg in ('-p', parameter)]],
            cpus=None if target_cpu is None else {target_cpu})
    else:
        process = start_python('from pseudo_stereo_ros.ros.bench_load import relay_main\n'
                               'raise SystemExit(relay_main())\n', [namespace, executor, *names],
                               cpus=None if target_cpu is None else {target_cpu})
    own_affinity = os.sched_getaffinity(0) if others else None
    if others:
        os.sched_setaffinity(0, others)
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    arrivals: List[tuple] = []
    diagnostics: Dict[str, float] = {}
    work: Dict[str, List[float]] = {}  # 'p50', 'p99' -> each /diagnostics period's [ms]
    source = None
    rss: List[tuple] = []
    try:
        node = rclpy.create_node('bench_load_sink', namespace=namespace, context=context)
        node.create_subscription(
            PointStamped, 'ball/position',
            lambda data: arrivals.append((decode_point(data)[0], time.time_ns())),
            QoSProfile(history=HistoryPolicy.KEEP_ALL), raw=True)

        def on_diagnostics(msg):
            for status in msg.status:
                if status.name.startswith(f'/{namespace}/fuser') or 'fuser' in status.name:
                    for item in status.values:
                        if item.key in ('observations', 'estimates'):
                            diagnostics[item.key] = float(item.value)
                        elif item.key.startswith('point received -> published p'):
                            work.setdefault(item.key.split()[-2], []).append(float(item.value))
        node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        executor_ = make_executor('events', context=context)
        executor_.add_node(node)
        position_topic = f'/{namespace}/ball/position'
        spin([], executor=executor_, context=context, duration_s=60.0,
             until=lambda: node.count_publishers(position_topic) > 0 or process.poll() is not None)
        if process.poll() is not None:
            raise RuntimeError(f'the {target} process exited with status {process.returncode}')
        source = start_python('from pseudo_stereo_ros.ros.bench_load import source_main\n'
                              'raise SystemExit(source_main())\n',
                              [f'/{namespace}', str(rate_hz), str(seconds)], cpus=others,
                              stdout=subprocess.PIPE, text=True)
        started = time.monotonic()
        cpu_start = _cpu_s(process.pid)
        next_sample = started
        next_report = started + (report_every_s or 0)
        while source.poll() is None:
            spin([], executor=executor_, context=context, duration_s=0.2)
            now = time.monotonic()
            if now >= next_sample:
                rss.append((now - started, _rss_kb(process.pid)))
                next_sample += 1.0
            if report_every_s and now >= next_report:
                print(f'    {now - started:7.0f} s: {target} RSS {rss[-1][1]} kB, '
                      f'{len(arrivals)} outputs received', flush=True)
                next_report += report_every_s
        output, _ = source.communicate()
        cpu_end, cpu_wall = _cpu_s(process.pid), time.monotonic() - started
        fields = output.split()
        sent, first_ns, late_p99 = int(fields[1]), int(fields[2]), float(fields[3])
        # The tail, and a /diagnostics published after it (period 1 s).
        settle = time.monotonic() + 3.0
        spin([], executor=executor_, context=context, duration_s=1.2)
        spin([], executor=executor_, context=context, duration_s=max(settle - time.monotonic(), 0),
             until=lambda: target != 'fuser' or diagnostics.get('observations', 0) >= sent)
        rss.append((time.monotonic() - started, _rss_kb(process.pid)))
        executor_.shutdown(timeout_sec=1.0)
    finally:
        if source is not None and source.poll() is None:
            source.kill()
            source.wait()
        close([], context=context)
        stop_processes([process], timeout_s=15.0)
        if own_affinity:
            os.sched_setaffinity(0, own_affinity)
    since = first_ns + int(WARM_UP_S * _NS)
    latencies = [(received - stamp) / _NS for stamp, received in arrivals if stamp >= since]
    if target == 'fuser':
        taken, outputs = int(diagnostics.get('observations', 0)), diagnostics.get('estimates')
    else:
        taken, outputs = len(arrivals), len(arrivals)
    return {'latencies_s': latencies, 'sent': sent, 'taken': taken,
            'outputs': None if outputs is None else int(outputs), 'received': len(arrivals),
            'rss_kb': rss, 'source_late_p99_ms': late_p99,
            'work_p50_ms': float(np.median(work['p50'])) if work.get('p50') else None,
            'work_p99_ms': max(work['p99']) if work.get('p99') else None,
            'cpu_fraction': (cpu_end - cpu_start) / cpu_wall if None not in (cpu_start, cpu_end)
            else float('nan')}


def rss_growth(samples) -> tuple:
    """Return (kB after 10% of the run, kB at the end) of ``rss_kb`` samples."""
    values = [(t, kb) for t, kb in samples if kb is not None]
    if not values:
        return float('nan'), float('nan')
    end_t = values[-1][0]
    early = next((kb for t, kb in values if t >= 0.1 * end_t), values[0][1])
    return early, values[-1][1]
