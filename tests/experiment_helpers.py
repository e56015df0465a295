"""Shared helpers of the experiment-runner tests: a private Xvfb, a scratch project layout, and
running ``python -m fovexp`` in a subprocess."""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

import fovexp
from fovexp.experiment.interfaces import FlipTimes
from fovexp.experiment.tasks.trial import Key
from fovexp.experiment.trackers.gaze import GazeSample, monotonic_us
from fovexp.experiment.trackers.simulated import ClockedGaze
from fovexp.stimuli import scenes

REPO = Path(__file__).resolve().parent.parent
PYTHON = sys.executable


def _free_display() -> int:
    # from 300: clear of xvfb-run -a, which counts up from 99 (CI runs .ci/wheel-smoke beside
    # the suite)
    for n in range(300, 400):
        if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists():
            return n
    raise RuntimeError("no free X display number")


def _die_with_parent() -> None:
    """In the child before it runs: SIGTERM when the process that started it exits (Linux's
    PR_SET_PDEATHSIG)."""
    import ctypes
    import signal

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # 1: PR_SET_PDEATHSIG


@contextlib.contextmanager
def private_xvfb(size: str = "1280x720", outlive_block: bool = False) -> Iterator[str]:
    """A private ``Xvfb`` with one ``size`` screen (24-bit) for the block: its DISPLAY name.
    Skips when Xvfb is not installed; fails when it does not start. With ``outlive_block``
    the server is not stopped at the block's end but when this process exits: PsychoPy's
    pyglet keeps its connection to the display open until then, and Xlib ends a process whose
    server went away with exit status 1 (pytest's, after every test passed)."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb)")
    n = _free_display()
    proc = subprocess.Popen([exe, f":{n}", "-screen", "0", f"{size}x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            preexec_fn=_die_with_parent if outlive_block else None)
    sock = Path(f"/tmp/.X11-unix/X{n}")
    for _ in range(100):
        if sock.exists() or proc.poll() is not None:
            break
        time.sleep(0.05)
    if proc.poll() is not None or not sock.exists():
        proc.kill()
        pytest.fail(f"Xvfb :{n} did not start")
    try:
        yield f":{n}"
    finally:
        if not outlive_block:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()


@pytest.fixture(scope="session")
def xvfb_display():
    """A DISPLAY for PsychoPy windows: the existing one, or a private ``Xvfb`` started here."""
    pytest.importorskip("psychopy", reason="PsychoPy is not installed (fovexp[experiment])")
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    with private_xvfb(outlive_block=True) as display:
        os.environ["DISPLAY"] = display
        try:
            yield display
        finally:
            del os.environ["DISPLAY"]


def x_key(screen, name: str) -> float:
    """Press and release key ``name`` (xdotool's name: ``Return``, ``Escape``) through the X
    server, as a keyboard delivers it, with the window of ``screen`` (a PsychoScreen) focused;
    returns ``time.monotonic()`` just before it was sent. Skips without xdotool."""
    exe = shutil.which("xdotool")
    if exe is None:
        pytest.skip("xdotool is not installed (apt-get install xdotool)")
    wid = str(screen.win.winHandle._window)
    subprocess.run([exe, "windowfocus", "--sync", wid], check=True, timeout=10)
    t = time.monotonic()
    subprocess.run([exe, "key", name], check=True, timeout=10)
    return t


def make_workspace(root: Path) -> Path:
    """A scratch project: ``protocols/`` (copied, editable) and ``results/``; the images come
    from the test session's stimulus folder (``$FOVEXP_STIMULI``, tests/conftest.py).

    The shipped protocols name their dependencies as ``<experiment>`` folders of the results
    root: run from ``root`` (or given ``results_root=root / "results"``) they find the dry runs'
    own results.
    """
    (root / "protocols").mkdir(parents=True)
    for p in (REPO / "protocols").glob("*.yaml"):
        shutil.copy(p, root / "protocols" / p.name)
    shutil.copytree(REPO / "protocols" / "displays", root / "protocols" / "displays")
    (root / "results").mkdir()
    return root


def edit_protocol(ws: Path, name: str, **changes) -> Path:
    """A copy of the workspace's protocol ``name`` with ``changes`` (dotted keys for nested
    ones, ``None`` removes a key), written beside it as ``edited-<name>.yaml``."""
    import yaml

    path = ws / "protocols" / f"{name}.yaml"
    data = yaml.safe_load(path.read_text())
    for key, value in changes.items():
        node = data
        *parents, last = key.split(".")
        for p in parents:
            node = node[p]
        if value is None:
            node.pop(last)
        else:
            node[last] = value
    out = ws / "protocols" / f"edited-{name}.yaml"
    out.write_text(yaml.safe_dump(data))
    return out


def run_cli(args: list[str], cwd: Path, timeout: float = 300,
            env_update: dict[str, str | None] | None = None) -> subprocess.CompletedProcess:
    """``python -m fovexp ARGS`` in ``cwd``; ``env_update`` sets (or, with None, removes)
    environment variables."""
    env = dict(os.environ)
    for k, v in (env_update or {}).items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run([PYTHON, "-m", "fovexp", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def popen_cli(args: list[str], cwd: Path) -> subprocess.Popen:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.Popen([PYTHON, "-m", "fovexp", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for_trials(proc: subprocess.Popen, trials_csv: Path, rows: int,
                    timeout_s: float) -> int:
    """Poll a running session's trial log until it holds ``rows`` rows, the process ends or
    ``timeout_s`` passes; the rows it held last (to kill a session part-way, at a known
    point)."""
    from fovexp.experiment.records.logs import read_trials

    deadline = time.monotonic() + timeout_s
    n = 0
    while time.monotonic() < deadline and proc.poll() is None:
        if trials_csv.exists():
            n = len(read_trials(trials_csv)[0])
            if n >= rows:
                break
        time.sleep(0.05)
    return n


class ScriptedGaze(ClockedGaze):
    """Gaze that follows ``path(t_s) -> (x, y) | None`` (None: invalid), sampled at ``rate_hz``
    from :meth:`start`: crosses the blanking radius at a known time. Not validated at the start
    of a session (the script does not look at calibration targets)."""

    name = "scripted"
    validated = False

    def __init__(self, path: Callable[[float], tuple[float, float] | None],
                 rate_hz: float = 600.0, clock_us: Callable[[], int] = monotonic_us) -> None:
        super().__init__(rate_hz, clock_us)
        self.path = path

    def _sample(self, i: int) -> GazeSample:
        t = self._time_us(i)
        pt = self.path(t / 1e6)
        ok = pt is not None
        x, y = pt if pt is not None else (math.nan, math.nan)
        assert self._t0 is not None
        return GazeSample(t, self._t0 + t, x, y, ok, x, y, ok)


class StubScreen:
    """A window-free :class:`fovexp.experiment.interfaces.Screen` for session tests: it draws
    nothing, records what each frame would show, gives scripted input per frame-loop poll
    (``inputs``: poll number from 1 -> events) and answers messages with
    ``answer(text, keys, timeout_s)`` (default: the first key; Q on the failed-validation
    screen; None on the tracker-lost screen, whose loop polls)."""

    def __init__(self, size, fullscreen=False, cross_px=10.0, dry_run=True, refresh_hz=60.0,
                 screen=0, inputs=None, answer=None, cal_answer=None, operator_keys=None) -> None:
        self.size = tuple(size)
        self.screen = screen
        self.refresh_hz = 60.0 if dry_run else float(refresh_hz)
        self.inputs = dict(inputs or {})
        self.answer = answer
        self.polls = 0
        self.test = None
        self.frames: list[tuple[bool, object]] = []  # (blank, test half shown)
        self.messages: list[str] = []
        self.closed = False
        self.cal_answer = cal_answer
        self.cal_views: list[str] = []
        self.operator_keys = dict(operator_keys or {})
        self.operator_calls = 0

    def measure_display(self):
        return self.refresh_hz, self.size, self.size

    def message(self, text, keys, timeout_s, each_frame=None):
        try:
            return self._message(text, keys, timeout_s)
        finally:
            if each_frame is not None:
                each_frame()  # as the real screen does after its flips

    def _message(self, text, keys, timeout_s):
        self.messages.append(text)
        if self.answer is not None:
            return self.answer(text, keys, timeout_s)
        if keys == ["q", "escape"]:  # the tracker-lost screen polls
            time.sleep(timeout_s or 0.0)
            return None
        if keys and "r" in keys:
            return "q"  # the tracker failed validation: stop, do not recalibrate forever
        return keys[0] if keys else None

    def calibration_frame(self, view):
        """One frame of a calibration screen: its keys come from ``cal_answer(view)`` (default:
        Space on the head box; on the result screen Space when the validation passed, else Q
        then Y to confirm; nothing elsewhere)."""
        time.sleep(1 / 240)
        self.cal_views.append(type(view).__name__)
        if self.cal_answer is not None:
            return list(self.cal_answer(view))
        from fovexp.experiment.trackers.calibration import HeadBoxView, ResultView, TextView

        if isinstance(view, HeadBoxView):
            return ["space"]
        if isinstance(view, ResultView):
            return ["space"] if view.passed else ["q"]
        if isinstance(view, TextView) and view.prompt.startswith("Y: quit"):
            return ["y"]
        return []

    def take_operator_keys(self):
        """The operator's D/C keys: ``operator_keys`` maps the call number (from 1) to keys."""
        self.operator_calls += 1
        return set(self.operator_keys.get(self.operator_calls, ()))

    def set_reference(self, left) -> None:
        pass

    def set_test(self, right) -> None:
        """``right``: a render (:class:`fovexp.experiment.display.render.Rendered`) or an image."""
        self.test = getattr(right, "rgba8", right)

    def set_mirrored(self, mirrored: bool) -> None:
        self.mirrored = mirrored

    def prepare(self, blank: bool) -> None:
        self._blank = blank

    def flip(self) -> FlipTimes:
        ready = time.monotonic()
        time.sleep(1 / 240)
        self.frames.append((self._blank, self.test))
        return FlipTimes(time.monotonic(), ready)

    def draw(self, blank: bool) -> FlipTimes:
        self.prepare(blank)
        return self.flip()

    def info(self):
        return {"keyboard": {"backend": "stub", "key_time": "press"}, "pace_hz": None,
                "refresh_hz": self.refresh_hz}

    def poll_input(self):
        """The scripted events of this poll; a key is stamped as pressed now (the stub's
        keyboard stamps the press, as the window's does)."""
        self.polls += 1
        now = time.monotonic()
        return [Key(e.name, now) if isinstance(e, Key) and e.t_s is None else e
                for e in self.inputs.get(self.polls, [])]

    def mouse_position(self):
        return None

    def close(self) -> None:
        self.closed = True


class GreyEnhancer:
    """Stands in for the enhancer where its pictures and speed are not under test: each render
    takes ``delay_s`` and shows the f_e it was computed with as the test half's grey level (so
    a test reads from the screen which render was shown); it keeps the viewports it was given,
    and every instance made (``instances``: a test that reads them clears them first)."""

    instances: list[GreyEnhancer] = []
    backend = "fake"
    delay_s = 0.0
    fallback_reason: str | None = None

    def __init__(self, display=None, preset="paper", geometry=None) -> None:
        self.preset, self.geometry = preset, geometry
        self.viewports: list[tuple[int, int, int, int] | None] = []
        self.shape: tuple[int, ...] | None = None
        GreyEnhancer.instances.append(self)

    def set_image(self, image, foveated=False, sigma_px=None, viewport=None) -> None:
        self.shape = image.shape
        self.viewports.append(viewport)

    def enhance(self, gaze, params):
        if self.delay_s:
            time.sleep(self.delay_s)

        class Res:
            output = np.full(self.shape, params.f_e, np.float32)

        res = Res()
        res.params = params  # what the renderer reports as shown
        return res


def use_enhancer(monkeypatch, cls: type = GreyEnhancer) -> None:
    """The runner gets its enhancer from fovexp.make_enhancer (public API): hand it ``cls``."""
    monkeypatch.setattr(fovexp, "make_enhancer", lambda display, preset="paper", geometry=None,
                        table=None, backend="auto", ctx=None: cls(display, preset, geometry))


# -- commands in this process, and images for them ------------------------------------------------
def pattern(h: int, w: int, seed: int, dtype=np.uint8, channels: int = 3) -> np.ndarray:
    """Random pixels over every code of ``dtype`` (an image no flat-region shortcut applies to)."""
    hi = np.iinfo(dtype).max
    shape = (h, w, channels) if channels > 1 else (h, w)
    return np.random.default_rng(seed).integers(0, hi + 1, size=shape, dtype=np.int64).astype(
        dtype)


def write_png(path: Path, pixels: np.ndarray) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(scenes.png_bytes(pixels))
    return path


class Result(NamedTuple):
    returncode: int
    stdout: str
    stderr: str


def cli(capsys, args: list[str]) -> Result:
    """``fovexp ARGS`` in this process (a new Python for each would take seconds; the
    subprocess tests cover the installed command): exit status, stdout, stderr."""
    from fovexp.cli import main

    capsys.readouterr()
    try:
        rc = main(args)
    except SystemExit as exc:  # argparse's errors
        rc = int(exc.code or 0)
    out = capsys.readouterr()
    return Result(rc, out.out, out.err)
