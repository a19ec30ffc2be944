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
``colcon build`` of the package installs what ``ros2 run`` needs, and the executables start.

colcon comes from PyPI (colcon-common-extensions in the dev requirements).
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parent.parent
COLCON = Path(sys.executable).parent / 'colcon'
EXECUTABLES = ('detector', 'fuser', 'virtual_camera', 'monitor', 'bringup', 'bench_pipeline',
               'replay', 'record', 'pseudo_stereo', 'camera_detector')


@pytest.fixture(scope='module')
def install(tmp_path_factory) -> Path:
    """Build a copy of the package with colcon; return the install prefix of the package."""
    if not COLCON.exists():
        pytest.skip('colcon is not installed (make venv-dev)')
    work = tmp_path_factory.mktemp('colcon')
    source = work / 'src' / 'pseudo_stereo_ros'
    source.mkdir(parents=True)
    for name in ('package.xml', 'setup.py', 'setup.cfg', 'LICENSE'):
        shutil.copy2(REPO / name, source / name)
    for name in ('resource', 'config', 'pseudo_stereo_ros'):
        shutil.copytree(REPO / name, source / name,
                        ignore=shutil.ignore_patterns('__pycache__', '*.egg-info'))
    result = subprocess.run(
        [str(COLCON), '--log-base', str(work / 'log'), 'build', '--base-paths', str(work / 'src'),
         '--build-base', str(work / 'build'), '--install-base', str(work / 'install')],
        cwd=work, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return work / 'install' / 'pseudo_stereo_ros'


def test_install_tree_has_what_ros2_run_needs(install):
    share = install / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'pseudo_stereo_ros').is_file()
    assert (share / 'pseudo_stereo_ros' / 'package.xml').is_file()
    for name in ('fuser.yaml', 'detector.yaml', 'bringup.yaml', 'virtual_camera.yaml',
                 'camera_detector.yaml', 'fastdds_large_images.xml', 'rig/camera1.yaml',
                 'rig/camera2.yaml', 'rig/camera3.yaml'):
        assert (share / 'pseudo_stereo_ros' / 'config' / name).is_file(), name
    for name in EXECUTABLES:
        executable = install / 'lib' / 'pseudo_stereo_ros' / name
        assert executable.is_file() and os.access(executable, os.X_OK), name


def _installed_env(install: Path) -> dict:
    site = next(install.glob('lib/python3*/site-packages'))
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join([str(site)] + env.get('PYTHONPATH', '').split(os.pathsep))
    return env


def test_installed_package_finds_its_installed_config(install, tmp_path):
    code = ('import pseudo_stereo_ros.rig as r; import pseudo_stereo_ros.sim.scenarios as s; '
            'print(r.__file__); print(r.config_dir()); '
            's.default_rig()')
    result = subprocess.run([sys.executable, '-c', code], env=_installed_env(install),
                            cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    module_file, config = result.stdout.split()
    assert Path(module_file).is_relative_to(install)
    assert Path(config) == install / 'share' / 'pseudo_stereo_ros' / 'config'


@pytest.mark.parametrize('name, args, expected', [
    ('fuser', ['--ros-args', '-p', 'camera_names:=[]'], 'camera_names'),
    ('detector', ['--ros-args', '-p', 'open_kernel_px:=99'], 'open_kernel_px'),
    ('virtual_camera', ['--ros-args', '-p', 'scenario:=loop'], 'scenario'),
    ('camera_detector', ['--ros-args', '-p', 'source:=webcam'], 'source'),
    ('monitor', ['--ros-args', '-p', 'max_history:=0'], 'max_history'),
    ('replay', ['--ros-args'], 'parameter bag: required'),
    ('record', ['--ros-args'], 'parameter bag: required'),
    ('bringup', ['--help'], 'usage: bringup'),
    ('bench_pipeline', ['--help'], 'usage: bench_pipeline'),
    ('pseudo_stereo', ['--help'], 'usage: pseudo_stereo'),
])
def test_installed_executables_start(install, tmp_path, name, args, expected):
    # Every executable starts from the install tree (imports resolve, config is found) and
    # stops at once: with a clear error for a bad parameter, or after --help.
    executable = install / 'lib' / 'pseudo_stereo_ros' / name
    if '--ros-args' in args:
        args = args + ['-r', f'__ns:=/colcon{os.getpid()}']
    result = subprocess.run([str(executable)] + args,
                            env=_installed_env(install), cwd=tmp_path, capture_output=True,
                            text=True, timeout=60)
    assert expected in result.stdout + result.stderr
    assert result.returncode == (1 if '--ros-args' in args else 0)
