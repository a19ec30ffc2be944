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

"""Test set-up shared by every test: DDS stays on loopback, in a domain of this run's own."""

import os
from pathlib import Path

import pytest

# Set before anything imports rclpy, so in-process nodes and spawned processes agree.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(10 + os.getpid() % 90))

REPO = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / 'data'


@pytest.fixture
def repo_dir() -> Path:
    """Return the repository root."""
    return REPO


@pytest.fixture
def data_dir() -> Path:
    """Return test/data."""
    return DATA


@pytest.fixture
def context():
    """Yield an rclpy context of this test only (rclpy imported here: core tests need none)."""
    import rclpy
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)
