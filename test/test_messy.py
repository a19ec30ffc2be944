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
Messy input on near-synchronized cameras (``pseudo_stereo sweep --messy``), a tenth of its cases.

Bounds: no estimate is ever non-finite and the counts always balance (the package's rules for
bad input); ``trajectory``'s mean MAE under every perturbation stays below ``paper``'s on the
same input and its mean coverage at least ``paper``'s (a peer); where a perturbation adds no
wrong position that a fuser keeps (copies at a detection's own stamp are dropped as
duplicates; NaN pixels are dropped; a camera goes silent; arrival is reordered) no estimate
is over 0.5 m off, and where it drops no detection either, coverage stays at least 90 % in
every run (issue 11's bars for clean cases).  Perturbations that put wrong positions in
(wrong blobs, bursts, stamps shifted back) still give errors over 0.5 m in some runs (README,
"Messy input"): no bound is claimed there.
"""

from pseudo_stereo_ros.evaluation.messy import (LARGE_ERROR_M, messy_cases, perturb,
                                                PERTURBATIONS, run_messy, summarize_messy)
from pseudo_stereo_ros.evaluation.sweep import Case, make_rig, simulate_case
from pseudo_stereo_ros.plausibility import DEFAULT_MAX_SPEED_MPS
from pseudo_stereo_ros.sim.scenarios import make_scenario
import pytest

# Perturbations that put no wrong position in: the clean cases' bar on errors holds for them;
# of those, the ones that drop no detection keep the coverage bar too.
_HARMLESS = ('clean', 'duplicates', 'non_finite', 'silent', 'streamed')
_LOSSLESS = ('clean', 'duplicates', 'streamed')


def _run(case_seed, described, perturbation, **options):
    """Run the messy case of ``case_seed`` under a perturbation, once it is the one described."""
    case = next(c for c in messy_cases() if c.seed == case_seed)
    assert (case.rig, case.fps, case.offset, case.scenario) == described, case
    return run_messy(case, perturbation, **options)


def _assert_bar_and_paper(result):
    """Issue 11's 0.5 m and paper's largest error bound the largest; paper's MAE the MAE."""
    assert result.max_error_m < min(LARGE_ERROR_M, result.paper_max_error_m), result
    assert result.mae_mm < result.paper_mae_mm, result


@pytest.fixture(scope='module')
def summary():
    results = [run_messy(case, perturbation) for case in messy_cases()[::10]
               for perturbation in PERTURBATIONS]
    return summarize_messy(results)


def test_every_perturbation_keeps_counts_and_finite_estimates(summary):
    assert set(summary) == set(PERTURBATIONS)
    for perturbation, row in summary.items():
        assert row['non_finite'] == 0, perturbation
        assert row['unbalanced'] == 0, perturbation


def test_trajectory_below_paper_under_every_perturbation(summary):
    for perturbation, row in summary.items():
        assert row['mae_mm'] < row['paper_mae_mm'], (perturbation, row)
        assert row['coverage'] >= row['paper_coverage'], (perturbation, row)


@pytest.mark.parametrize('perturbation', _HARMLESS)
def test_perturbations_without_wrong_positions_keep_the_bar(summary, perturbation):
    assert summary[perturbation]['largest_m'] < LARGE_ERROR_M, summary[perturbation]
    if perturbation in _LOSSLESS:
        assert summary[perturbation]['lowest_coverage'] >= 0.9, summary[perturbation]


def test_perturb_changes_what_it_says():
    case = Case('default', 30.0, 0.05, 0.0, True, 'straight', seed=1)
    cameras = make_rig(case.rig)
    observations, _, _ = simulate_case(case, cameras)
    start = min(o.stamp_ns for o in observations)
    silent, streamed = perturb(observations, 'silent', fps=30.0, cameras=cameras, seed=0)
    assert not streamed
    assert not [o for o in silent if o.camera == 'camera2'
                and start + 3e8 <= o.stamp_ns <= start + 6e8]
    assert len(silent) < len(observations)
    arrival, streamed = perturb(observations, 'streamed', fps=30.0, cameras=cameras, seed=0)
    assert streamed and sorted(arrival) == sorted(observations)
    assert [o.stamp_ns for o in arrival] != sorted(o.stamp_ns for o in arrival)
    with pytest.raises(ValueError, match='unknown perturbation'):
        perturb(observations, 'gremlins', fps=30.0, cameras=cameras, seed=0)


def test_a_camera_silent_across_a_bounce_confirms_the_impact():
    # Camera 2 is silent from 0.3 s to 0.6 s of a falling ball (distorted rig, 30 fps, offset
    # 0.03) and returns just after the floor impact.  Its first detection, fresh, used to be
    # fitted without gating into the falling path: 1.70 m off, MAE 19.7 mm against paper's
    # 1.45.  It is off the path across the image of camera 1's rays, where the path's drift
    # while camera 1 alone carried it cannot move it, so it is judged and confirms the impact
    # with the next detection (31 mm at most, MAE 0.31 mm).
    result = _run(9128, ('distorted', 30.0, 0.03, 'bounce'), 'silent')
    assert result.max_error_m < LARGE_ERROR_M, result
    assert result.mae_mm < 0.95 * result.paper_mae_mm, result


def test_a_path_faster_than_any_ball_confirms_no_impact():
    # Bursts of wrong blobs across a bounce (distorted rig, 30 fps, synchronized; the draw
    # that found it): impacts were confirmed off fits of a few frames until the path ran at
    # 2,900 m/s, and a free jump off it, the estimate of a held detection, was 339 m off.  No
    # path faster than max_speed_mps confirms an impact now (1.46 m at most).  Found with the
    # previous test's change; before it this run took another course (0.99 m at most).  The
    # bounds: no estimate is farther off than the fastest ball flies in the whole flight, and
    # the MAE stays below paper's on the same input (31 against 35 mm; 2,323 mm with the
    # 339 m estimate).  The largest error, 1.46 m, is over paper's 0.53 m (README).
    result = _run(9122, ('distorted', 30.0, 0.0, 'bounce'), 'bursts', seed=2325404069)
    assert result.max_error_m < DEFAULT_MAX_SPEED_MPS * make_scenario('bounce').duration_s, \
        result
    assert result.mae_mm < result.paper_mae_mm, result


def test_a_free_jump_out_of_reach_is_no_estimate():
    # 10 % wrong blobs on the wide rig, 30 fps, offset 0.08, bouncing ball: after an impact
    # confirmed from two detections, the third was held and its estimate taken from a free
    # jump explaining the three, 3.57 m off.  Now that position must be within an impact's
    # reach of the path before it (twice the speed plus _JUMP_MARGIN_MPS since the last
    # frame fitted), as a confirmed impact must: 0.17 m at most.  Bound: paper's largest
    # error on the same input (0.25 m).
    result = _run(9080, ('wide', 30.0, 0.08, 'bounce'), 'strays10')
    assert result.max_error_m < result.paper_max_error_m, result


def test_a_late_wrong_blob_is_not_fitted():
    # Everything at once (wrong blobs, duplicates, NaN, early stamps, a silent camera,
    # streamed arrival) on the wide rig, 30 fps, synchronized: camera 2's detections arrive
    # 7 ms after camera 1's, so many arrive after a newer one (late), and late detections
    # were fitted without gating, wrong blobs among them: 1.08 m off.  A late one off the path
    # across the image of the other camera's rays is an outlier now.  Bounds: issue 11's
    # 0.5 m and paper's largest error on the same input (0.90 m).
    result = _run(9065, ('wide', 30.0, 0.0, 'bounce'), 'all')
    assert result.max_error_m < min(LARGE_ERROR_M, result.paper_max_error_m), result


def test_a_restarted_fit_stays_within_an_impacts_reach_of_the_lost_path():
    # Everything at once on the distorted rig, 30 fps, offset 0.03, bouncing ball: after an
    # impact, two detections in a row off the path (one a wrong blob) and a third restarted
    # the fit, and a velocity fit of its first four frames was 5.93 m off (paper's largest on
    # the same input: 0.83 m).  Until the new window has six frames its positions must be
    # within an impact's reach of the lost path: 0.16 m at most.  Bounds: issue 11's 0.5 m
    # and paper's largest error.
    result = _run(9131, ('distorted', 30.0, 0.03, 'bounce'), 'all')
    _assert_bar_and_paper(result)


def test_one_cameras_wrong_blobs_in_a_row_do_not_restart_the_path():
    # A burst of wrong blobs of camera 1 (default rig, 30 fps, offset 0.1, straight line),
    # camera 2 dropping the frame between two of them: three of camera 1's detections in a
    # row off the path restarted the fit from them, and the fit followed the burst (2.32 m
    # off, MAE 60 mm).  Three or more in a row of one camera alone are outliers now until
    # another camera's detection disagrees too; camera 2's agree, so the path goes on
    # (0.06 m at most).
    # Bounds: issue 11's 0.5 m and paper's largest error on the same input (1.54 m).
    result = _run(9024, ('default', 30.0, 0.1, 'straight'), 'bursts')
    _assert_bar_and_paper(result)


def test_one_wrong_blob_within_the_gate_does_not_widen_it():
    # 10 % wrong blobs (default rig, 30 fps, offset 0.03, bouncing ball): a wrong blob within
    # the gate, fitted, raised the running spread of innovations many times at once, and
    # with the gate widened by it later wrong blobs passed too (0.64 m off, MAE 25.9 mm).
    # One sample now counts at most _SPREAD_CLIP times the spread so far: 0.03 m at most,
    # MAE 1.3 mm.  Bounds: issue 11's 0.5 m and paper's largest error on the same input
    # (0.42 m).
    result = _run(9008, ('default', 30.0, 0.03, 'bounce'), 'strays10')
    _assert_bar_and_paper(result)


def test_a_burst_off_the_other_cameras_rays_is_not_taken_for_a_drift():
    # Bursts of camera 1's wrong blobs (default rig, 60 fps, offset 0.08, bouncing ball): two
    # in a row off the path the same way by chance were taken for a path that camera 2's rays
    # had pulled off camera 1's, and fitted (1.32 m off, MAE 41.9 mm: one of the runs the
    # spread's clip made worse, 0.48 m before it, on another course).  With one other camera
    # carrying the path, a drift moves the prediction only along the image of that camera's
    # rays; off it by more than 45 degrees, the detection is judged as any other: 0.13 m at
    # most, MAE 1.4 mm.  Bounds: issue 11's 0.5 m and paper's largest error (0.55 m).
    result = _run(9053, ('default', 60.0, 0.08, 'bounce'), 'bursts')
    _assert_bar_and_paper(result)


def test_a_path_carried_by_one_camera_falls_freely():
    # Bursts of camera 1's wrong blobs (wide rig, 30 fps, synchronized, bouncing ball), all
    # rejected: camera 2 alone carried the path, no window determined an acceleration, and the
    # constant-velocity fit of the whole window that then served missed gravity (0.74 m off,
    # MAE 8.9 mm).  The better of a velocity and a free fall serves now: 0.06 m at most, MAE
    # 0.5 mm (with the velocity alone 0.76 m).  Bounds: issue 11's 0.5 m and paper's largest
    # error on the same input (0.21 m).
    result = _run(9062, ('wide', 30.0, 0.0, 'bounce'), 'bursts')
    _assert_bar_and_paper(result)


def test_a_wrong_blob_among_a_restarts_first_frames_is_dropped():
    # Bursts of camera 1's wrong blobs (default rig, 60 fps, synchronized, straight line): the
    # path restarted from three detections, one of them a 14 px wrong blob; a restart's first
    # frames are not gated, no acceleration fit was determined, and the velocity fit with the
    # blob put the estimates 0.18-0.38 m off (0.95 m at most, MAE 17.6 mm).  The frame whose
    # removal alone explains the velocity fit's misfit is dropped as an outlier now (by the
    # fallback, or first when the window reaches six frames: either alone fixes this run):
    # 0.14 m at most, MAE 0.9 mm.  Bounds: issue 11's 0.5 m and paper's largest error on the
    # same input (0.49 m).
    result = _run(9030, ('default', 60.0, 0.0, 'straight'), 'bursts')
    _assert_bar_and_paper(result)


def test_a_wrong_blob_a_restart_started_from_is_dropped_when_gating_begins():
    # Bursts of camera 1's wrong blobs on the three-camera rig (60 fps, offset 0.1, 0.3 px
    # noise, straight line): the path restarted from three detections, one of them a 24 px
    # wrong blob, and fitted ungated it bent the restarted path (0.77 m off, MAE 15.3 mm).  When
    # the window reaches the six frames detections are gated by, a frame whose removal alone
    # explains a velocity or free fall's misfit is dropped as an outlier now: 0.32 m at most,
    # MAE 5.5 mm.  Bounds: issue 11's 0.5 m and paper's largest error on the same input
    # (1.01 m).
    result = _run(9237, ('three', 60.0, 0.1, 'straight'), 'bursts')
    _assert_bar_and_paper(result)
