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

"""A static type check (mypy) of the ROS-free core; its settings are in setup.cfg."""

from pathlib import Path

import pytest

mypy_api = pytest.importorskip('mypy.api')

REPO = Path(__file__).resolve().parent.parent


@pytest.mark.linter
def test_core_type_checks():
    stdout, stderr, status = mypy_api.run(['--config-file', str(REPO / 'setup.cfg'),
                                           str(REPO / 'pseudo_stereo_ros')])
    assert status == 0, stdout + stderr
