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
The shared node glue: params-file checks, the warning about a second fuser, one spin loop.

The params-file matcher is checked against rcl itself: for each section key,
a node sees the section's value (rcl applied it) exactly when the check says
the section matches.
"""

import ast
import itertools
import os
from pathlib import Path
import re
import subprocess
import sys
import threading
import time

from pseudo_stereo_ros.ros.fuser_node import FuserNode
from pseudo_stereo_ros.ros.node_tools import (check_params_files, make_executor, params_files,
                                              spin, split_executor_option, StartupError)
import pytest
import rclpy

ROS_DIR = Path(__file__).resolve().parent.parent / 'pseudo_stereo_ros' / 'ros'
BIN = Path(sys.executable).parent
_COUNTER = itertools.count()


def _context(args):
    context = rclpy.Context()
    rclpy.init(args=args, context=context)
    return context


def _params(tmp_path, text):
    path = tmp_path / f'params{next(_COUNTER)}.yaml'
    path.write_text(text)
    return str(path)


def test_a_misspelt_parameter_is_named_with_the_nearest_declared_one(tmp_path):
    path = _params(tmp_path, '/**/fuser:\n  ros__parameters:\n    sync_tolerence_s: 0.004\n'
                             '    max_gap_s: 0.05\n')
    args = ['--ros-args', '--params-file', path]
    context = _context(args)
    try:
        node = FuserNode(context=context, namespace=f'/pt{os.getpid()}')
        try:
            warnings = check_params_files([node], args)
            # The typo is not applied (rcl ignores undeclared keys): the default stays.
            assert node.get_parameter('sync_tolerance_s').value == 0.001
            assert node.get_parameter('max_gap_s').value == 0.05
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert len(warnings) == 1, warnings
    assert "'sync_tolerence_s'" in warnings[0] and "did you mean 'sync_tolerance_s'" in warnings[0]
    assert '\n' not in warnings[0]


# key, node namespace, node name: does rcl apply the section to the node?
SECTIONS = [
    ('/**/fuser', '/a/b', 'fuser'),
    ('/**/fuser', '/', 'fuser'),
    ('/**', '/a', 'fuser'),
    ('fuser', '/', 'fuser'),
    ('fuser', '/a', 'fuser'),
    ('/a/fuser', '/a', 'fuser'),
    ('/a/fuser', '/b', 'fuser'),
    ('/*/fuser', '/a', 'fuser'),
    ('/*/fuser', '/a/b', 'fuser'),
    ('/a/**', '/a/b', 'fuser'),
    ('/**/fusr', '/', 'fuser'),
]


@pytest.mark.parametrize('key, namespace, name', SECTIONS)
def test_section_matching_agrees_with_rcl(tmp_path, key, namespace, name):
    """The check warns about a section exactly when rcl does not apply it to the node."""
    path = _params(tmp_path, f'{key}:\n  ros__parameters:\n    max_gap_s: 0.05\n')
    args = ['--ros-args', '--params-file', path]
    context = _context(args)
    try:
        node = FuserNode(context=context, namespace=namespace, node_name=name)
        try:
            applied = node.get_parameter('max_gap_s').value == 0.05
            warnings = check_params_files([node], args)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    # Not applied: either the name is close (a typo: named) or no section matches at all.
    assert bool(warnings) == (not applied), (key, namespace, warnings)
    if not applied and key.endswith('fusr'):
        assert "did you mean 'fuser'" in warnings[0]


def test_a_shared_file_warns_only_about_what_no_node_uses(tmp_path):
    """bringup.yaml-style files: sections of other nodes are fine; a near-miss name is not."""
    path = _params(tmp_path, '/**/detector:\n  ros__parameters:\n    min_area_px: 4.0\n'
                             '/**/fuser:\n  ros__parameters:\n    max_gap_s: 0.05\n'
                             '/**/fuserr:\n  ros__parameters:\n    max_gap_s: 0.05\n')
    context = _context([])
    try:
        node = FuserNode(context=context, namespace=f'/ps{os.getpid()}')
        try:
            warnings = check_params_files([node], files=[path])
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    assert len(warnings) == 1 and "'/**/fuserr'" in warnings[0], warnings
    assert "did you mean 'fuser'" in warnings[0]


def test_the_fuser_executable_warns_about_a_typo_in_one_line(tmp_path):
    path = _params(tmp_path, '/**/fuser:\n  ros__parameters:\n    sync_tolerence_s: 0.004\n')
    process = subprocess.Popen(
        [str(BIN / 'fuser'), '--ros-args', '-r', f'__ns:=/typo{os.getpid()}', '--params-file',
         path], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    guard = threading.Timer(60.0, process.kill)  # a missing warning fails, never hangs
    guard.start()
    try:
        # The warning comes after construction ('fusing'), before spinning; read until the
        # first line after it (the node logs nothing else then), not until the pipe closes.
        fusing = False
        for line in process.stdout:
            lines.append(line)
            if fusing:
                break
            fusing = 'fusing' in line
    finally:
        guard.cancel()
        process.terminate()
        process.wait(timeout=30)
    text = ''.join(lines)
    warned = [line for line in text.splitlines() if 'sync_tolerence_s' in line]
    assert len(warned) == 1 and 'WARN' in warned[0], text
    assert "did you mean 'sync_tolerance_s'" in warned[0]


def test_params_files_and_the_executor_option_are_read_from_the_command_line():
    argv = ['fuser', '--executor', 'single', '--ros-args', '--params-file', 'a.yaml', '-p',
            'x:=1', '--params-file', 'b.yaml']
    kind, rest = split_executor_option(argv)
    assert kind == 'single' and '--executor' not in rest and 'single' not in rest
    assert params_files(rest) == ['a.yaml', 'b.yaml']
    assert split_executor_option(['fuser'])[0] == 'events'
    with pytest.raises(StartupError, match='--executor fast'):
        split_executor_option(['fuser', '--executor', 'fast'])


def test_a_second_fuser_on_the_same_topics_is_warned_about():
    """Two fusers publish /ball/position twice over: each one sees the other."""
    namespace = f'/dup{os.getpid()}'
    context = _context([])
    nodes = []
    try:
        nodes = [FuserNode(context=context, namespace=namespace, node_name=f'fuser{k}',
                           parameter_overrides=[]) for k in range(2)]
        executor = make_executor('single', context=context)
        for node in nodes:
            executor.add_node(node)
        spin([], executor=executor, context=context, duration_s=20.0,
             until=lambda: all(node.position_watch.check() >= 1 for node in nodes))
        others = [node.position_watch.others for node in nodes]
        executor.shutdown()
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert others == [1, 1]


def test_one_fuser_sees_no_other_publisher():
    context = _context([])
    try:
        node = FuserNode(context=context, namespace=f'/single{os.getpid()}')
        try:
            executor = make_executor('single', context=context)
            spin([node], executor=executor, context=context, duration_s=1.5)
            assert node.position_watch.check() == 0
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_spin_stops_at_the_deadline_and_on_until():
    context = _context([])
    try:
        node = rclpy.create_node('spinner', context=context)
        ticks = []
        node.create_timer(0.01, lambda: ticks.append(time.monotonic()))
        start = time.monotonic()
        spin([node], context=context, duration_s=0.3)
        assert 0.25 <= time.monotonic() - start < 5.0
        assert ticks  # the timer ran under the default executor (EventsExecutor)
        spin([node], context=context, until=lambda: len(ticks) >= 40, duration_s=30.0)
        assert len(ticks) >= 40
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


# -- structure ------------------------------------------------------------------------------------

def _imports(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            yield node.module or '', node.level
        elif isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, 0


def test_no_node_imports_another_node():
    """Shared helpers live in node_tools.py and messages.py, not in a node module."""
    offenders = []
    for path in sorted(ROS_DIR.glob('*_node.py')):
        for module, _ in _imports(path):
            if module.split('.')[-1].endswith('_node'):
                offenders.append(f'{path.name} imports {module}')
    assert offenders == []


def test_every_executable_spins_through_node_tools():
    """One spin loop (node_tools.spin): no module calls rclpy.spin or spin_once itself."""
    pattern = re.compile(r'\brclpy\.spin(_once|_until_future_complete)?\(|\.spin_once\(')
    offenders = [f'{path.name}:{number}' for path in sorted(ROS_DIR.glob('*.py'))
                 if path.name != 'node_tools.py'
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if pattern.search(line)]
    assert offenders == []


@pytest.mark.parametrize('name', ['bench_pipeline.py', 'bench_load.py'])
def test_benchmarks_import_at_the_top(name):
    tree = ast.parse((ROS_DIR / name).read_text())
    nested = [f'{node.name}:{inner.lineno}' for node in ast.walk(tree)
              if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
              for inner in ast.walk(node) if isinstance(inner, (ast.Import, ast.ImportFrom))]
    assert nested == []
