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
Convert the lfg table-tennis sessions into small ROS 2 bags for the tests.

Run once by hand (not installed, never run by tests)::

    .venv/bin/python tools/convert_lfg.py /path/to/lfg_table_tennis test/data/lfg_table_tennis

For each ``<session>_clean.json`` it writes the bag directory
``<out>/<session>/`` (mcap, rosbag2 version 9) with one
``geometry_msgs/msg/PointStamped`` topic ``/camera_k/ball/image_point`` per
camera: ``point.x`` = u, ``point.y`` = v (raw pixels), header stamp = the
recorded stamp, ``frame_id`` = ``camera_k``, log time = the stamp.  Flights
are not marked: the gaps between them (about 0.7 s) are far longer than any
gap within a flight.  It copies the calibration files and the licence
unchanged (files that already exist identical are left alone) and writes the
attribution README.

Stray detections: the source lists of a flight sometimes carry detections of
later flights (seconds later) after the flight's own run.  Each flight of
each camera is sorted by stamp and cut at the first gap longer than
``STRAY_GAP_NS``; only the first run is kept.  Within a flight detector misses
leave gaps of up to 47 ms, so 50 ms keeps them.  A stamp that carries two
different detections (once in n1_n1's camera_2: two blobs in one frame) is
ambiguous; both are dropped.  One ball per topic: a flight's detections end
where the next flight's begin (camera_3 of n1_n1 still sees the previous ball
for a while after the launcher fires the next; those tail points are
dropped).
"""

import argparse
from collections import Counter
import filecmp
import json
from pathlib import Path
import shutil
import sys

from pseudo_stereo_ros.formats.bagio import write_observations
from pseudo_stereo_ros.records import Observation

SESSIONS = ('n1_n1', 'n3_p1_v14', 'p2_p2')
CALIBRATIONS = ('22276213_calibration.yaml', '22276209_calibration.yaml',
                '22276216_calibration.yaml')
SOURCE_REPO = 'xiaoqingyu0113/lfg'
SOURCE_COMMIT = '4a8700cf9d1b9e1e0a2455000f14cb2bb341d6d3'
STRAY_GAP_NS = 50_000_000

README = """\
# lfg table-tennis sessions as ROS 2 bags (test data)

Source: the public repository `{repo}` (https://github.com/{repo}), commit
`{commit}`, MIT licence: see `LICENSE` in this folder (Copyright (c) 2024 Qingyu Xiao).
Three recording sessions ({sessions}) of a real table-tennis rig: three calibrated,
free-running ~168 fps cameras (1280x1024, radtan distortion), ball detections from a neural
detector, ROS header stamps.  Converted by `tools/convert_lfg.py` (run once by hand):

    .venv/bin/python tools/convert_lfg.py <lfg_table_tennis data folder> test/data/lfg_table_tennis

## Contents
- `<session>/`: a rosbag2 (version 9, mcap) with `/camera_1/ball/image_point`,
  `/camera_2/ball/image_point`, `/camera_3/ball/image_point` (geometry_msgs/msg/PointStamped:
  point.x = u, point.y = v in raw pixels, header stamp = the recorded stamp, frame_id =
  the camera name). Flights are implicit: gaps between flights are ~0.7 s.
  Stray detections (a run separated from its flight's run by more than 50 ms) and the two
  detections of one camera_2 frame of n1_n1 that share a stamp are dropped; one ball per
  topic: a flight's detections end where the next flight's begin (the previous ball's tail).
- Calibrations, unchanged: camera_1 = `22276213_calibration.yaml`,
  camera_2 = `22276209_calibration.yaml`, camera_3 = `22276216_calibration.yaml`
  (`x_cam = R x_world + t`, world z up, metres).

## Messages per bag
{counts}
"""


def _flight_run(rows: list) -> list:
    """Return the first run of a flight's rows sorted by stamp, cut at a gap > STRAY_GAP_NS."""
    rows = sorted(rows, key=lambda row: row[0])
    for k in range(1, len(rows)):
        if rows[k][0] - rows[k - 1][0] > STRAY_GAP_NS:
            return rows[:k]
    return rows


def session_observations(path: Path) -> tuple:
    """Return (observations, dropped) of one ``<session>_clean.json``."""
    data = json.loads(path.read_text())
    observations, dropped = [], 0
    for camera, flights in sorted(data.items()):
        runs = []
        for flight in flights:
            rows = [(int(r[2]) * 1_000_000_000 + int(r[3]), float(r[0]), float(r[1]))
                    for r in flight]
            runs.append(_flight_run(rows))
            dropped += len(rows) - len(runs[-1])
        kept = []
        for k, run in enumerate(runs):
            # One ball per topic: a flight ends where the next one starts (the previous ball
            # may still be in view of a camera while the launcher fires the next).
            end = runs[k + 1][0][0] if k + 1 < len(runs) and runs[k + 1] else None
            tail = [row for row in run if end is not None and row[0] >= end]
            dropped += len(tail)
            kept.extend(row for row in run if end is None or row[0] < end)
        repeats = Counter(stamp for stamp, _, _ in kept)
        for stamp, u, v in kept:
            if repeats[stamp] > 1:
                dropped += 1
                continue
            observations.append(Observation(camera, stamp, u, v))
    return observations, dropped


def _copy(src: Path, dst: Path) -> None:
    if dst.exists() and filecmp.cmp(src, dst, shallow=False):
        return
    shutil.copyfile(src, dst)


def main(argv=None) -> int:
    """Convert the sessions; return the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('source', type=Path, help='the lfg_table_tennis data folder')
    parser.add_argument('output', type=Path, help='output folder (test/data/lfg_table_tennis)')
    args = parser.parse_args(argv)
    args.output.mkdir(parents=True, exist_ok=True)
    counts = []
    for session in SESSIONS:
        observations, dropped = session_observations(args.source / f'{session}_clean.json')
        bag = args.output / session
        if bag.exists():
            shutil.rmtree(bag)
        write_observations(bag, observations)
        per_camera = {}
        for obs in observations:
            per_camera[obs.camera] = per_camera.get(obs.camera, 0) + 1
        line = (f'- {session}: ' + ', '.join(f'{c} {n}' for c, n in sorted(per_camera.items()))
                + f' ({dropped} stray or ambiguous detections dropped)')
        counts.append(line)
        print(line)
    for name in CALIBRATIONS + ('LICENSE',):
        _copy(args.source / name, args.output / name)
    (args.output / 'README.md').write_text(README.format(
        repo=SOURCE_REPO, commit=SOURCE_COMMIT, sessions=', '.join(SESSIONS),
        counts='\n'.join(counts)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
