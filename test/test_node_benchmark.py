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

"""``bench_pipeline --quick`` runs and prints every row with its baseline; no timing checked."""

import re
import subprocess
import sys


def test_quick_benchmark_prints_each_quantity_with_its_baseline_ratio(repo_dir):
    # Its own process: the benchmark sets the Fast DDS profile for large images.
    result = subprocess.run([sys.executable, '-m', 'pseudo_stereo_ros.ros.bench_pipeline',
                             '--quick'],
                            capture_output=True, text=True, timeout=180, cwd=repo_dir)
    assert result.returncode == 0, result.stdout + result.stderr
    rows = {}
    for line in result.stdout.splitlines():
        match = re.match(r'\s+(\S.*?)\s{2,}(\d+)\s+([\d.]+)\s+([\d.]+)(.*)$', line)
        if match:
            rows[match.group(1)] = (int(match.group(2)), match.group(5))
    measured = ['detector, full frame', 'detector, search window 48 px',
                'fuser node, point received -> published',
                'end to end, image stamp -> /ball/position',
                'shutter -> /ball/position published',
                'fuser node, 2 x 1,000 Hz, stamp -> received']
    baselines = ['baseline: cv2.cvtColor BGR->HSV, full frame',
                 'baseline: core Fuser.update, same points',
                 'baseline: image stamp -> bare subscriber',
                 'baseline: bare PointStamped hop',
                 'baseline: bare relay, same rate and core']
    assert set(measured + baselines) <= set(rows), result.stdout
    for label in measured:
        count, rest = rows[label]
        assert count > 0, label
        assert re.search(r'<= [\d.]+ (ok|OVER)\s+\d+\.\d\dx', rest), (label, rest)
    assert all(rows[label][0] > 0 for label in baselines), result.stdout
    # The load rows say what was lost, the CPU share and the memory of the fuser.
    for label in ('fuser node, 2 x 1,000 Hz, stamp -> received',
                  'baseline: bare relay, same rate and core'):
        assert re.search(r'p99 [\d.]+ .*lost \d+ of \d+ in, \d+ out; CPU \d+% .*RSS [\d.]+ -> '
                         r'[\d.]+ MiB', rows[label][1]), (label, rows[label][1])
