"""Window-free runner logic: value stepping, the blanking decision, gaze simulation, the
simulated participant and crash-safe logs (validation metrics: test_quality.py)."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fovexp import FovexpError, load_display
from fovexp.experiment.gaze import BlankingMonitor, FixationGeometry, GazeSample
from fovexp.experiment.logs import TRIAL_COLUMNS, BatchLog, TrialLog, read_trials
from fovexp.experiment.participant import SimTruth, SimulatedParticipant
from fovexp.experiment.trackers.simulated import SimGazeParams, SimulatedGaze
from fovexp.experiment.trial import (
    BlankingLog,
    FrameTimer,
    Key,
    TrialState,
    ValueAdjuster,
    Wheel,
    wheel_notches,
)

DISPLAY = load_display("lg-oled55cx")


@pytest.fixture(scope="module")
def fix() -> FixationGeometry:
    return FixationGeometry(DISPLAY)


def point_at(fix: FixationGeometry, ecc: float, angle: float = 0.0) -> tuple[float, float]:
    """The normalised screen point at ``ecc`` degrees from the cross in direction ``angle``,
    found by bisection on the geometry's own eccentricity."""
    lo, hi = 0.0, 0.45
    d = np.array([math.cos(angle), math.sin(angle)])
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        p = (0.5 + mid * d[0], 0.5 + mid * d[1] * DISPLAY.width_px / DISPLAY.height_px)
        if fix.eccentricity(p) < ecc:
            lo = mid
        else:
            hi = mid
    r = 0.5 * (lo + hi)
    return 0.5 + r * d[0], 0.5 + r * d[1] * DISPLAY.width_px / DISPLAY.height_px


def sample(t_us: int, p: tuple[float, float] | None, left_ok: bool = True,
           right_ok: bool = True) -> GazeSample:
    x, y = p if p is not None else (math.nan, math.nan)
    return GazeSample(t_us, t_us, x, y, left_ok and p is not None, x, y,
                      right_ok and p is not None)


# -- value stepping --------------------------------------------------------------------------

def test_adjuster_steps_and_clamps() -> None:
    a = ValueAdjuster(0.0, 0.4, 0.02, 0.005, 0.1)
    assert a.apply(Wheel(3)) and a.value == pytest.approx(0.16)
    assert a.apply(Wheel(-2, fine=True)) and a.value == pytest.approx(0.15)
    a.apply(Wheel(100))
    assert a.value == 0.4
    assert not a.apply(Wheel(1))  # at the end of the range: no change, still counted
    assert a.notches == 3 + 2 + 100 + 1
    a.apply(Wheel(-1000))
    assert a.value == 0.0


def test_wheel_notches_sum_fractions() -> None:
    """A high-resolution wheel reports fractions of a notch: they add up to whole notches."""
    assert wheel_notches([(1.0, False), (2.0, False), (-1.0, True)]) == (
        [Wheel(3), Wheel(-1, fine=True)], (0.0, True))
    wheel, carry = wheel_notches([(0.4, False)] * 3)
    assert wheel == [Wheel(1)] and carry == (pytest.approx(0.2), False)
    wheel, carry = wheel_notches([(0.4, False), (0.5, False)], carry)  # carried over
    assert wheel == [Wheel(1)] and carry == (pytest.approx(0.1), False)
    wheel, carry = wheel_notches([(-0.3, False)] * 4, carry)  # back the other way
    assert wheel == [Wheel(-1)] and carry == (pytest.approx(-0.1), False)  # 0.1 - 1.2 = -1.1
    # ten tenths are one notch, although their float sum is 0.999...
    assert wheel_notches([(0.1, False)] * 10)[0] == [Wheel(1)]
    assert wheel_notches([(0.1, False)] * 20)[0] == [Wheel(2)]
    # a fine half-turn and a coarse half-turn are not one coarse notch
    wheel, carry = wheel_notches([(0.6, True), (0.6, False)])
    assert wheel == [] and carry == (pytest.approx(0.6), False)


@given(st.lists(st.tuples(st.integers(-5, 5), st.booleans()), max_size=200))
@settings(max_examples=50, deadline=None)
def test_adjuster_never_leaves_range(moves: list[tuple[int, bool]]) -> None:
    a = ValueAdjuster(0.0, 45.0, 1.5, 0.25, 20.0)
    for n, fine in moves:
        a.apply(Wheel(n, fine))
        assert 0.0 <= a.value <= 45.0
        # Values stay on the step grid (no floating-point drift).
        assert abs(a.value * 4 - round(a.value * 4)) < 1e-6


def test_trial_state_confirm_and_pause() -> None:
    s = TrialState(ValueAdjuster(0, 1, 0.1, 0.01, 0.5), 60.0)
    assert s.handle([Wheel(1), Key("return")]) is None  # nothing counts before the first frame
    s.flip(10.0, False, "")
    assert s.handle([Wheel(2)]) == "changed" and s.value == pytest.approx(0.7)
    assert s.handle([Key("escape")]) == "pause"
    assert s.handle([Key("return")]) == "confirm"
    s.finish(11.5)
    assert s.response_time_s == pytest.approx(1.5)


def test_frame_timer_counts_dropped() -> None:
    t = FrameTimer(120.0)
    times = [0, 1 / 120, 2 / 120, 4 / 120, 5 / 120, 5.5 / 120 + 1 / 120]
    for x in times:
        t.flip(x)
    assert t.dropped == 1 and len(t.intervals) == 5


def test_blanking_log_episodes() -> None:
    b = BlankingLog()
    pattern = [0, 0, 1, 1, 1, 0, 0, 1, 0, 1, 1]
    for i, blank in enumerate(pattern):
        b.frame(i * 0.01, bool(blank), "outside" if blank else "")
    b.close(0.2)
    assert [(round(e.start_s, 3), round(e.end_s, 3), e.frames) for e in b.episodes] == [
        (0.02, 0.05, 3), (0.07, 0.08, 1), (0.09, 0.2, 2)]
    # time-weighted, on the episodes' own time base: (0.03 + 0.01 + 0.11) / 0.2
    assert b.fraction == pytest.approx(sum(e.end_s - e.start_s for e in b.episodes) / 0.2)
    assert b.fraction == pytest.approx(0.75)
    assert (b.frames, b.blanked) == (11, 6)


def test_blanked_fraction_counts_how_long_a_black_frame_stayed() -> None:
    """One black frame followed by a dropped (0.49 s) interval: black for 98 % of the trial, not
    for 1 of 4 frames."""
    b = BlankingLog()
    for t, blank in ((0.0, False), (0.01, True), (0.50, False), (0.51, False)):
        b.frame(t, blank, "outside" if blank else "")
    b.close(0.51)
    assert b.fraction == pytest.approx(0.49 / 0.51)
    assert b.episodes[0].end_s - b.episodes[0].start_s == pytest.approx(0.49)


# -- blanking decision -----------------------------------------------------------------------

def test_blanking_switches_exactly_at_radius(fix: FixationGeometry) -> None:
    """Paper section 5.1: gaze farther than 1.25 deg from the cross -> black; back -> shown."""
    mon = BlankingMonitor(fix, 1.25, timeout_s=0.05)
    eccs = [0.0, 0.5, 1.0, 1.2, 1.249, 1.2499, 1.2501, 1.251, 1.5, 3.0, 1.2501, 1.2499, 0.3]
    for angle in (0.0, math.pi / 2, 2.3, -0.7):
        for i, e in enumerate(eccs):
            p = point_at(fix, e, angle)
            assert fix.eccentricity(p) == pytest.approx(e, abs=1e-6)
            d = mon.update([sample(1000 * i, p)], 1000 * i)
            assert d.blank == (e > 1.25), (angle, e)
            assert d.reason == ("outside" if e > 1.25 else "")


def test_blanking_radius_in_centimetres_on_the_screen(fix: FixationGeometry) -> None:
    """The 1.25 deg radius from the display's own measurements, not from the geometry code: a
    point d cm from the cross (the screen centre, where the line of sight is perpendicular) is
    atan(d / distance) away, so the edge lies at d = distance * tan(1.25 deg) in any direction."""
    mon = BlankingMonitor(fix, 1.25, timeout_s=0.05)
    d_cm = DISPLAY.distance_cm * math.tan(math.radians(1.25))  # 1.560 cm on the LG OLED55CX
    for i, angle in enumerate((0.0, math.pi / 2, 2.3, -0.7)):
        for j, scale in enumerate((0.995, 1.005)):
            dx, dy = scale * d_cm * math.cos(angle), scale * d_cm * math.sin(angle)
            p = (0.5 + dx / DISPLAY.width_cm, 0.5 + dy / DISPLAY.height_cm)
            expected = math.degrees(math.atan(math.hypot(dx, dy) / DISPLAY.distance_cm))
            assert fix.eccentricity(p) == pytest.approx(expected, rel=1e-3)
            t = 1000 * (2 * i + j)
            assert mon.update([sample(t, p)], t).blank == (scale > 1), (angle, scale)


def test_blanking_invalid_lost_and_off_screen(fix: FixationGeometry) -> None:
    mon = BlankingMonitor(fix, 1.25, timeout_s=0.05)
    assert mon.update([], 0).reason == "lost"  # nothing yet
    c = (0.5, 0.5)
    assert not mon.update([sample(0, c)], 0).blank
    assert mon.update([sample(1000, None)], 1000).reason == "invalid"
    # One valid eye is enough (its position is used).
    one = GazeSample(2000, 2000, 0.5, 0.5, True, math.nan, math.nan, False)
    assert not mon.update([one], 2000).blank
    assert not mon.update([], 2000 + 49_000).blank
    assert mon.update([], 2000 + 51_000).reason == "lost"  # stream stalled
    assert mon.update([sample(60_000, (1.2, 0.5))], 60_000).reason == "outside"
    # The latest sample decides: an excursion that is back by the frame is not blanked.
    far = point_at(fix, 3.0)
    assert not mon.update([sample(70_000, far), sample(71_000, c)], 71_000).blank


# -- simulated gaze --------------------------------------------------------------------------

def test_simulated_gaze_is_seeded_and_plausible(fix: FixationGeometry) -> None:
    clock = [0]
    params = SimGazeParams(saccade_rate=0.5, blink_rate=0.5)
    a = SimulatedGaze(fix, seed=5, params=params, clock_us=lambda: clock[0])
    b = SimulatedGaze(fix, seed=5, params=params, clock_us=lambda: clock[0])
    a.start()
    b.start()
    sa, sb = [], []
    for step in range(1, 201):  # 20 s, polled at irregular intervals for one of the two
        clock[0] = step * 100_000
        sa += a.poll()
        if step % 3 == 0 or step == 200:
            sb += b.poll()
    assert len(sa) == len(sb) == 600 * 20 + 1
    assert sa == sb
    dt = np.diff([s.system_time_us for s in sa])
    assert np.all(np.abs(dt - 1e6 / 600) <= 1)
    ecc = np.array([fix.eccentricity(s.point) for s in sa])
    valid = np.isfinite(ecc)
    assert 0.9 < valid.mean() < 1.0  # blinks and dropouts
    assert np.median(ecc[valid]) < 0.6  # mostly fixating
    assert (ecc[valid] > 1.25).mean() > 0.005  # but sometimes looking away


def test_simulated_gaze_stream_is_independent_of_validation_and_disconnects(
        fix: FixationGeometry) -> None:
    """Sample i depends on the seed, i and the target looked at only: looking at a validation
    target for a while (at whatever time) changes only the samples while on it, and a lost
    connection only hides samples; the samples on a target are the same whenever it is
    looked at."""
    clock = [0]
    ref = SimulatedGaze(fix, seed=9, clock_us=lambda: clock[0])
    other = SimulatedGaze(fix, seed=9, clock_us=lambda: clock[0])
    early = SimulatedGaze(fix, seed=9, clock_us=lambda: clock[0])
    for g in (ref, other, early):
        g.start()
    early.look_at((0.3, 0.3))  # on the target from 0.15 s on, throughout
    got_ref, got_other, got_early = [], [], []
    for step in range(1, 31):  # 3 s
        clock[0] = step * 100_000
        got_ref += ref.poll()
        got_early += early.poll()
        if step == 5:
            other.look_at((0.3, 0.3))  # a validation target, mid-stream: on it 0.65 ... 0.95 s
        if step == 8:
            other.look_at(None)
        if step == 11:
            other.set_connected(False)
        if step == 16:
            other.set_connected(True)
        got_other += other.poll()
    assert len(got_ref) == 1801
    by_time = {s.device_time_us: s for s in got_ref}
    hidden = [s for s in got_ref if not any(o.device_time_us == s.device_time_us
                                            for o in got_other)]
    assert 2 * 600 * 0.1 < len(hidden) <= 600 * 0.6  # the disconnected half second
    on = [o for o in got_other if 650_000 <= o.device_time_us < 950_000]
    off = [o for o in got_other if not 650_000 <= o.device_time_us < 950_000]
    assert len(on) == 180 and off and all(by_time[o.device_time_us] == o for o in off)
    pts = np.array([o.point for o in on if o.valid])
    assert np.allclose(pts.mean(axis=0), (0.3, 0.3), atol=0.002)
    # the samples on the target do not depend on when it was looked at
    early_by_time = {s.device_time_us: s for s in got_early}
    assert all(early_by_time[o.device_time_us] == o for o in on)
    # each sample carries the simulated eyes' positions: 71.5 cm from the screen, 63 mm apart
    s0 = next(o for o in got_other if o.left_valid and o.right_valid)
    assert s0.left_origin_mm == pytest.approx((-31.5, 0.0, 715.0))
    assert s0.right_origin_mm == pytest.approx((31.5, 0.0, 715.0))


# -- simulated participant -------------------------------------------------------------------

@pytest.mark.parametrize(("param", "lo", "hi", "step", "fine", "start"), [
    ("f_e", 0.0, 0.4, 0.02, 0.005, 0.39),
    ("s_k", 0.0, 45.0, 1.5, 0.25, 2.0),
    ("blur_rate", 0.0, 1.5, 0.02, 0.005, 0.0),
])
def test_participant_reaches_noise_free_target(param, lo, hi, step, fine, start) -> None:
    truth = SimTruth()
    p = SimulatedParticipant(truth, seed=3, speed=1.0, noise_scale=0.0)
    adj = ValueAdjuster(lo, hi, step, fine, start)
    target = p.begin(param, "ours", 0.34, 1.9, lo, hi, step, fine)
    assert target == pytest.approx(truth.value(param, "ours", 0.34, 1.9))
    t, overshoot, rt = 0.0, 0.0, None
    while t < 60:
        for ev in p.poll(t, adj.value, True):
            if isinstance(ev, Key):
                rt = t
                break
            adj.apply(ev)
            overshoot = max(overshoot, (adj.value - target) * np.sign(target - start))
        if rt is not None:
            break
        t += 0.01
    assert rt is not None and 1.0 < rt < 30.0
    assert abs(adj.value - target) <= fine / 2 + 1e-9
    assert overshoot >= step - 1e-9  # it overshoots with coarse steps, then corrects


def test_participant_waits_while_blanked() -> None:
    p = SimulatedParticipant(SimTruth(), seed=1, speed=1.0)
    p.begin("f_e", "contrast", 0.34, None, 0, 0.4, 0.02, 0.005)
    assert all(p.poll(t / 10, 0.0, False) == [] for t in range(100))


def test_sim_truth_yaml(tmp_path: Path) -> None:
    f = tmp_path / "truth.yaml"
    f.write_text("sk_slope: -2\nnoise_sd: {s_k: 0.5}\nvalidation_blur_rate: {ours: 0.7}\n"
                 "table: {source: x, rows: [{blur_rate: 0.1, f_e: 0.1, s_k: 10, s_f: 2}, "
                 "{blur_rate: 0.5, f_e: 0.3, s_k: 20, s_f: 3}]}\n")
    t = SimTruth.load(f)
    assert t.value("f_e", "contrast", 0.3, None) == pytest.approx(0.2)
    assert t.value("s_k", "ours", 0.3, 3.5) == pytest.approx(15 - 2 * (3.5 - 2.5))
    assert t.value("blur_rate", "ours", None, None) == 0.7
    f.write_text("sk_slop: 1\n")
    with pytest.raises(FovexpError, match=r"sk_slop=1: Extra inputs are not permitted"):
        SimTruth.load(f)


def test_fixation_window_is_physical_whatever_the_enhancers_model(tmp_path: Path) -> None:
    """The release preset's geometry describes the prototype's screen, not the participant's:
    the 1.25 deg window is still measured on the display profile (here a protocol with
    preset release, whose enhancer geometry is 'release')."""
    import yaml

    from fovexp.experiment.protocol import load_protocol
    from fovexp.experiment.session import Session, SessionOptions
    from fovexp.geometry import ViewingGeometry

    from experiment_helpers import make_workspace

    ws = make_workspace(tmp_path / "ws")
    path = ws / "protocols" / "calibration-fe.yaml"
    data = yaml.safe_load(path.read_text())
    data["preset"], data["geometry"] = "release", "release"
    path.write_text(yaml.safe_dump(data))
    lp = load_protocol(path)
    assert lp.spec.geometry_model == "release"
    s = Session(lp, SessionOptions(participant="X01", results_root=tmp_path / "results",
                                   window_size=(480, 270)))  # the test session's scenes
    exact = ViewingGeometry.for_image(DISPLAY, DISPLAY.width_px, DISPLAY.height_px, "exact")
    pt = point_at_offset(s.fixation, (0.5, 0.5), 1.25)
    px = exact.gaze_px(pt)
    want = float(exact.eccentricity_deg(np.array(px[0]), np.array(px[1]),
                                        exact.gaze_px((0.5, 0.5))))
    assert want == pytest.approx(1.25, abs=1e-6)
    release = ViewingGeometry.for_image(DISPLAY, DISPLAY.width_px, DISPLAY.height_px, "release")
    rpx = release.gaze_px(pt)
    assert abs(float(release.eccentricity_deg(np.array(rpx[0]), np.array(rpx[1]),
                                              release.gaze_px((0.5, 0.5)))) - 1.25) > 0.1


def point_at_offset(fix: FixationGeometry, target: tuple[float, float], deg: float):
    lo, hi = 0.0, 0.2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if fix.angle_between((target[0] + mid, target[1]), target) < deg:
            lo = mid
        else:
            hi = mid
    return target[0] + lo, target[1]


# -- logs ------------------------------------------------------------------------------------

def row(i: int, session: str = "20260101-000000") -> dict:
    r = dict.fromkeys(TRIAL_COLUMNS)
    r.update(participant="P01", session=session, experiment="calibration-fe",
             protocol_sha256="ab" * 32, trial_index=i, practice=i == 0, repetition=0,
             image="scene-00", blur_rate=0.34, method="contrast", adjusted_parameter="f_e",
             f_e=0.1 * i, start_value=0.2, final_value=0.1 * i, response_time_s=1.5,
             wheel_events=4, blanked_fraction=0.0, dropped_frames=0, tracker="simulated",
             seed=1, software_version="0.1.0", timestamp="2026-01-01T00:00:00+00:00")
    return r


def test_trial_log_round_trip_and_torn_tail(tmp_path: Path) -> None:
    path = tmp_path / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    rows, n = read_trials(path)
    assert [r["trial_index"] for r in rows] == [0, 1, 2] and n == path.stat().st_size
    assert rows[0]["practice"] is True and rows[1]["s_k"] is None
    assert rows[2]["final_value"] == pytest.approx(0.2)
    # Every cut of the last row's bytes reads as the first two rows (torn row dropped).
    full = path.read_bytes()
    last_start = full.rfind(b"\n", 0, len(full) - 1) + 1
    for cut in range(last_start + 1, len(full)):
        path.write_bytes(full[:cut])
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            rows, n = read_trials(path)
        assert [r["trial_index"] for r in rows] == [0, 1], cut
        assert n == last_start and any("torn" in str(x.message) for x in w)
    # Reopening cuts the torn tail off, so the next row starts on a fresh line.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = TrialLog(path)
    log.append(row(2))
    rows, _ = read_trials(path)
    assert [r["trial_index"] for r in rows] == [0, 1, 2]
    assert (tmp_path / "trials.csv.torn").exists()


def test_corrupt_middle_row_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    lines = path.read_text().splitlines(keepends=True)
    lines[2] = lines[2].replace(",contrast,", ",contrast,extra,")
    path.write_text("".join(lines))
    with pytest.raises(FovexpError, match="line 3: 25 fields, expected 24"):
        read_trials(path)


def test_one_trials_format_for_runner_and_analysis(tmp_path: Path) -> None:
    """The runner and the analysis read trials.csv with the same definition (logformat)."""
    from fovexp.results import format as logformat
    from fovexp.results.loading import COLUMNS, read_trials_file

    assert COLUMNS is logformat.TRIAL_COLUMNS is TRIAL_COLUMNS
    path = tmp_path / "P01" / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    with open(path, "ab") as fh:
        fh.write(b"P01,20260101-000000,calibration-fe,ab")  # torn by a kill
    with pytest.warns(UserWarning, match="line 5: torn last row"):
        runner_rows, _ = read_trials(path)
    with pytest.warns(UserWarning, match="line 5: torn last row"):
        frame, excl = read_trials_file(path)
    assert [r["trial_index"] for r in runner_rows] == list(frame["trial_index"]) == [0, 1, 2]
    assert [e.rule for e in excl] == ["R1 torn last row"]


def test_batch_log(tmp_path: Path) -> None:
    path = tmp_path / "gaze.csv"
    log = BatchLog(path, ["a", "b"])
    log.extend([(1, 0.5), (2, None)])
    assert log.flush(sync=True) == 2
    with open(path, "a") as fh:
        fh.write("3,0.")  # torn by a kill
    BatchLog(path, ["a", "b"]).flush()
    assert path.read_text() == "a,b\n1,0.5\n2,\n"


def test_a_resumed_log_of_an_older_format_is_upgraded(tmp_path: Path) -> None:
    """A frame log of version 1 (docs/LOGS.md, "Format versions") reopened by a newer runner:
    its header becomes the current one and its rows get the new column empty, so the rows
    appended after it line up; the reader sees the old rows with the column empty. A file
    whose columns are not an older version's is refused, naming it."""
    from fovexp.results.format import FRAME_COLUMNS, FRAME_LOG_VERSIONS
    from fovexp.results.frames import read_frame_log

    path = tmp_path / "frames-s.csv"
    v1 = FRAME_LOG_VERSIONS[1]
    path.write_text(",".join(v1) + "\n0,0,0,1.0,,0,0,0.2,990000,0.3,1000000\n0,0,1,1.0")
    log = BatchLog(path, FRAME_COLUMNS)
    log.add((0, 0, 1, 1.008, 0.008, 0, 0, 0.2, 999000, 0.3, 1008000, 1007000))
    log.flush(sync=True)
    frames = read_frame_log(path)
    assert path.read_text().splitlines()[0] == ",".join(FRAME_COLUMNS)
    assert list(frames["frame"]) == [0, 1]  # the torn row cut, then the new one
    assert frames["decide_system_time_us"].isna().tolist() == [True, False]
    assert path.with_name(path.name + ".torn").read_text() == "0,0,1,1.0\n"
    other = tmp_path / "other.csv"
    other.write_text("x,y\n1,2\n")
    with pytest.raises(FovexpError, match="other.csv: its columns are not those"):
        BatchLog(other, FRAME_COLUMNS)


def test_synced_flush_waits_for_a_flush_under_way(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The periodic flusher has taken rows 1 and is writing them when the trial ends: the trial's
    synced flush of rows 2 must not return before rows 1 are on disk, nor write 2 before 1."""
    import threading

    from fovexp.experiment import logs

    started, release = threading.Event(), threading.Event()
    real = logs.format_line

    def slow(row):  # the first batch stalls in the middle of its write
        if row == (1, 1):
            started.set()
            assert release.wait(5)
        return real(row)

    monkeypatch.setattr(logs, "format_line", slow)
    path = tmp_path / "gaze.csv"
    log = BatchLog(path, ["a", "b"])
    log.add((1, 1))
    background = threading.Thread(target=log.flush)
    background.start()
    assert started.wait(5)
    log.add((2, 2))
    synced = threading.Thread(target=log.flush, kwargs={"sync": True})
    synced.start()
    # waits for the write under way: it cannot return before release.set(), however slow the
    # machine (0.3 s is only how long a flush that does not wait has to show it)
    synced.join(0.3)
    assert synced.is_alive()
    release.set()
    background.join(5)
    synced.join(5)
    assert path.read_text() == "a,b\n1,1\n2,2\n"


# -- display check ---------------------------------------------------------------------------

def test_display_check_refresh_rate() -> None:
    from fovexp.experiment.window import check_display

    size = (DISPLAY.width_px, DISPLAY.height_px)
    info = check_display(119.2, size, size, DISPLAY)
    assert info["measured_refresh_hz"] == 119.2 and info["profile_refresh_hz"] == 120
    # The 120 Hz screen running at 60 Hz stops the session.
    with pytest.raises(FovexpError, match=r"measured refresh 60\.0 Hz.*says 120 Hz"):
        check_display(60.0, size, size, DISPLAY)
    with pytest.raises(FovexpError, match="could not be measured"):
        check_display(None, size, size, DISPLAY)


def test_display_check_scaling() -> None:
    from fovexp.experiment.window import check_display

    size = (DISPLAY.width_px, DISPLAY.height_px)
    # 150 % desktop scaling: the window reports fewer pixels than the framebuffer has.
    with pytest.raises(FovexpError) as err:
        check_display(120.0, (2560, 1440), size, DISPLAY)
    msg = str(err.value)
    assert "window is 2560x1440 px (framebuffer 3840x2160)" in msg and "3840x2160" in msg
    assert "--skip-display-check" in msg and "\n" not in msg
    with pytest.raises(FovexpError, match="framebuffer 1920x1080"):
        check_display(120.0, size, (1920, 1080), DISPLAY)
    # Both problems at once are both named.
    with pytest.raises(FovexpError, match=r"60\.0 Hz.*; window is"):
        check_display(60.0, (2560, 1440), (2560, 1440), DISPLAY)
