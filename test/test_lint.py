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

"""The ROS linters (ament flake8 and pep257) and the licence header of every source file."""

import ast
from pathlib import Path
import subprocess
import sys

from ament_flake8.main import main_with_errors
from ament_pep257.main import main as pep257_main
import pytest

REPO = Path(__file__).resolve().parent.parent
SOURCE_DIRS = ('pseudo_stereo_ros', 'test', 'tools')
HEADER_FILE = REPO / 'pseudo_stereo_ros' / '__init__.py'


def _python_files():
    files = [REPO / 'setup.py']
    for directory in SOURCE_DIRS:
        files.extend(sorted((REPO / directory).rglob('*.py')))
    return [f for f in files if 'data' not in f.relative_to(REPO).parts]


def _paths():
    return [str(REPO / d) for d in SOURCE_DIRS if (REPO / d).is_dir()] + [str(REPO / 'setup.py')]


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    status, errors = main_with_errors(argv=_paths())
    assert status == 0, f'Found {len(errors)} code style errors / warnings:\n' + '\n'.join(errors)


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    assert pep257_main(argv=_paths()) == 0, 'Found code style errors / warnings'


def _header() -> str:
    lines = []
    for line in HEADER_FILE.read_text(encoding='utf-8').splitlines():
        if not line.startswith('#'):
            break
        lines.append(line)
    return '\n'.join(lines)


@pytest.mark.copyright
@pytest.mark.linter
def test_every_source_file_carries_the_licence_header():
    header = _header()
    assert 'Licensed under the Apache License, Version 2.0' in header
    body = header.split('\n', 1)[1]  # the copyright line may name another year
    missing = [str(f.relative_to(REPO)) for f in _python_files()
               if not f.read_text(encoding='utf-8').startswith('# Copyright ')
               or body not in f.read_text(encoding='utf-8')]
    assert not missing, 'files without the Apache-2.0 header: ' + ', '.join(missing)


PACKAGE = REPO / 'pseudo_stereo_ros'
ROS_DIR = PACKAGE / 'ros'


def _is_ros_import(name: str) -> bool:
    top = name.split('.')[0]
    return (top in ('rclpy', 'rcl_interfaces', 'builtin_interfaces', 'rosidl_runtime_py')
            or top.endswith('_msgs'))


def _imports(path: Path):
    """Yield (line, absolute module name) of every import in a module, relative ones resolved."""
    parts = list(path.relative_to(REPO).with_suffix('').parts)
    package = parts if parts[-1] == '__init__' else parts[:-1]
    package = [p for p in package if p != '__init__']
    for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                module = '.'.join(base + ([node.module] if node.module else []))
                names = [module] if node.module else [f'{module}.{a.name}' for a in node.names]
            else:
                names = [node.module]
            for name in names:
                yield node.lineno, name


def _core_modules():
    return sorted(p for p in PACKAGE.rglob('*.py') if ROS_DIR not in p.parents)


def test_only_the_ros_subpackage_imports_rclpy_or_messages():
    # Parsed, not listed: a new module outside pseudo_stereo_ros/ros/ is core by its place.
    bad = [f'{path.relative_to(REPO)}:{line}: {name}'
           for path in _core_modules() for line, name in _imports(path)
           if _is_ros_import(name) or name.startswith('pseudo_stereo_ros.ros')]
    assert not bad, 'core modules importing ROS: ' + ', '.join(bad)
    # The check must see what it checks: the ROS glue does import rclpy.
    assert any(_is_ros_import(name)
               for path in ROS_DIR.rglob('*.py') for _, name in _imports(path))


def test_core_imports_without_rclpy_in_a_fresh_interpreter():
    modules = sorted(
        '.'.join(p.relative_to(REPO).with_suffix('').parts).removesuffix('.__init__')
        for p in _core_modules() if p.stem != '__main__')
    code = ('import importlib, sys\n'
            f'for name in {modules!r}:\n'
            '    importlib.import_module(name)\n'
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in\n"
            "             ('rclpy', 'std_msgs', 'geometry_msgs', 'sensor_msgs',\n"
            "              'rosidl_runtime_py', 'visualization_msgs', 'diagnostic_msgs',\n"
            "              'builtin_interfaces'))\n"
            'print(len(sys.modules))\n'
            'assert not bad, bad\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=120, cwd=REPO)
    assert result.returncode == 0, result.stderr
    assert len(modules) >= 8  # calibration, camera, geometry, fusion, simulation, cli, ...


def test_fusion_and_trajectory_do_not_import_each_other():
    # trajectory builds on fusion (the paper method stands in for a fit's first frames);
    # fusion's factory finds the trajectory class by name (estimator_class), without an
    # import back, at module level or inside a function.
    fusion = {name for _, name in _imports(PACKAGE / 'fusion.py')}
    trajectory = {name for _, name in _imports(PACKAGE / 'trajectory.py')}
    assert not any(name.startswith('pseudo_stereo_ros.trajectory') for name in fusion), fusion
    assert 'pseudo_stereo_ros.fusion' in trajectory, trajectory
    # Every method the factory offers resolves to its class.
    from pseudo_stereo_ros.estimator import estimator_class
    from pseudo_stereo_ros.fusion import Fuser, METHODS
    from pseudo_stereo_ros.trajectory import TrajectoryFuser
    assert {method: estimator_class(method) for method in METHODS} == {
        'paper': Fuser, 'naive': Fuser, 'trajectory': TrajectoryFuser}
