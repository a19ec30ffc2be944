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
Held-out evaluation on the real table-tennis bags (test/data/lfg_table_tennis).

Bounds.  The interpolation oracle sees both cameras on both sides of each held-out stamp; its
error (1.1-1.8 px median) is the floor set by detection noise and calibration.  ``paper`` is
causal: it extrapolates at most one frame period (6 ms) from its two newest anchors, so it may
sit above the floor, but by less than 0.5 px (2 mm at camera_3's ~5 m, where 1 px is ~4 mm).
``naive`` pairs points up to one frame period apart: at the median ball speed of 6.6 m/s that is
up to 4 cm of motion, which shows in the tail; ``paper`` must beat it clearly: a lower median,
and a p90 at most 80% of naive's.
"""

from pathlib import Path

import numpy as np
from pseudo_stereo_ros.camera import Camera
from pseudo_stereo_ros.cli.main import main
from pseudo_stereo_ros.evaluation.holdout import estimates_at, holdout
from pseudo_stereo_ros.formats.bagio import read_observations
from pseudo_stereo_ros.records import Estimate
import pytest

LFG = Path(__file__).resolve().parent / 'data' / 'lfg_table_tennis'
SESSIONS = ('n1_n1', 'n3_p1_v14', 'p2_p2')
CAMERAS = {'camera_1': '22276213', 'camera_2': '22276209', 'camera_3': '22276216'}


def _calibration(camera):
    return LFG / f'{CAMERAS[camera]}_calibration.yaml'


@pytest.fixture(scope='module')
def cameras():
    return {name: Camera.from_file(_calibration(name), name=name) for name in CAMERAS}


@pytest.fixture(scope='module')
def results(cameras):
    return {session: holdout(cameras, read_observations(LFG / session)) for session in SESSIONS}


@pytest.mark.parametrize('session', SESSIONS)
def test_paper_near_oracle_floor(results, session):
    result = results[session]
    oracle, paper = result['oracle'], result['paper']
    assert paper.count > 80
    assert oracle.median_px < 2.0  # the README's floor is 1.1-1.7 px
    assert paper.median_px < oracle.median_px + 0.5, (paper.median_px, oracle.median_px)


@pytest.mark.parametrize('session', SESSIONS)
def test_paper_clearly_beats_naive(results, session):
    result = results[session]
    paper, naive = result['paper'], result['naive']
    assert paper.median_px < naive.median_px - 0.1, (paper.median_px, naive.median_px)
    assert paper.p90_px < 0.8 * naive.p90_px, (paper.p90_px, naive.p90_px)


@pytest.mark.parametrize('session', SESSIONS)
def test_same_events_and_coverage(results, session):
    result = results[session]
    stamps = result['oracle'].stamps_ns
    for method in ('paper', 'naive'):
        np.testing.assert_array_equal(result[method].stamps_ns, stamps)
        # The causal fuser covers (almost) every held-out stamp the oracle covers.
        assert result[method].available >= 0.95 * result['oracle'].available


def test_deterministic(cameras, results):
    again = holdout(cameras, read_observations(LFG / 'p2_p2'))
    for method, result in results['p2_p2'].items():
        np.testing.assert_array_equal(again[method].errors, result.errors)
        np.testing.assert_array_equal(again[method].stamps_ns, result.stamps_ns)


def test_estimates_at_interpolates_within_max_gap():
    base = 1_721_679_791_000_000_000
    estimates = [Estimate(base, 'a', 0.0, 0.0, 0.0, 'pseudo'),
                 Estimate(base + 4_000_000, 'b', 4.0, -4.0, 8.0, 'pseudo'),
                 Estimate(base + 504_000_000, 'a', 0.0, 0.0, 0.0, 'pseudo')]
    query = np.array([base + 1_000_000, base + 4_000_000, base + 5_000_000, base - 1], np.int64)
    points = estimates_at(estimates, query, max_gap_ns=100_000_000)
    np.testing.assert_allclose(points[0], [1.0, -1.0, 2.0])
    np.testing.assert_allclose(points[1], [4.0, -4.0, 8.0])
    assert np.isnan(points[2]).all()  # bracketing estimates 0.5 s apart: a gap between flights
    assert np.isnan(points[3]).all()


def test_estimates_at_takes_the_later_of_two_cameras_within_the_sync_tolerance():
    # Two cameras' estimates 0.5 ms apart are one instant: the later, which saw both frames,
    # stands for it; one camera's two estimates are never merged.
    base = 1_721_679_791_000_000_000
    estimates = [Estimate(base, 'a', 0.0, 0.0, 0.0, 'pseudo'),
                 Estimate(base + 6_000_000, 'a', 9.0, 9.0, 9.0, 'pseudo'),
                 Estimate(base + 6_500_000, 'b', 6.0, 0.0, 0.0, 'sync')]
    query = np.array([base + 3_000_000, base + 6_000_000], np.int64)
    points = estimates_at(estimates, query, max_gap_ns=100_000_000)
    np.testing.assert_allclose(points[0], [3.0 * 6.0 / 6.5, 0.0, 0.0])
    np.testing.assert_allclose(points[1], [6.0 * 6.0 / 6.5, 0.0, 0.0])
    points = estimates_at(estimates, query, max_gap_ns=100_000_000, sync_tolerance_ns=0)
    np.testing.assert_allclose(points, [[4.5, 4.5, 4.5], [9.0, 9.0, 9.0]])
    same_camera = [e._replace(camera='a') for e in estimates]
    np.testing.assert_allclose(estimates_at(same_camera, query, max_gap_ns=100_000_000)[1],
                               [9.0, 9.0, 9.0])


def test_cli_table(capsys):
    args = ['holdout'] + [str(LFG / session) for session in SESSIONS]
    for camera in CAMERAS:
        args += ['--camera', f'{camera}={_calibration(camera)}']
    assert main(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    rows = [line.split() for line in lines[2:]]
    assert [(row[0], row[1]) for row in rows] == [
        (session, method) for session in SESSIONS
        for method in ('paper', 'naive', 'trajectory', 'oracle')]


def test_cli_unknown_camera(capsys):
    args = ['holdout', str(LFG / 'p2_p2'), '--held-out', 'camera_9']
    for camera in CAMERAS:
        args += ['--camera', f'{camera}={_calibration(camera)}']
    assert main(args) == 2
    assert 'camera_9' in capsys.readouterr().err
