"""A missing optional part (issue 11) is named with the extra that installs it, in one line:
PsychoPy (``experiment``), moderngl (``gpu``), tobii-research (``tracker``). Each is made
unimportable for the test the way an environment without it is (``sys.modules[name] = None``
makes ``import name`` raise ModuleNotFoundError)."""

from __future__ import annotations

import sys

import pytest

from fovexp import FovexpError


def _without(monkeypatch, *names: str) -> None:
    for name in names:
        for loaded in [m for m in sys.modules if m == name or m.startswith(name + ".")]:
            monkeypatch.delitem(sys.modules, loaded)
        monkeypatch.setitem(sys.modules, name, None)


def test_no_psychopy_names_the_experiment_extra(monkeypatch):
    from fovexp.experiment.display.window import PsychoScreen

    _without(monkeypatch, "psychopy")
    with pytest.raises(FovexpError) as exc:
        PsychoScreen((64, 48), fullscreen=False, dry_run=True)
    msg = str(exc.value)
    assert "pip install 'fovexp[experiment]'" in msg and "DISPLAY" not in msg
    assert "\n" not in msg


def test_no_moderngl_names_the_gpu_extra(monkeypatch):
    from fovexp import load_display, make_enhancer

    _without(monkeypatch, "moderngl")
    with pytest.raises(FovexpError, match=r"pip install 'fovexp\[gpu\]'"):
        make_enhancer(load_display("lg-oled55cx"), backend="gpu")
    # auto falls back to the CPU, and says why in words a lab can act on (the runner says it
    # once: "enhancer on the CPU: ..."), never about GL contexts
    auto = make_enhancer(load_display("lg-oled55cx"), backend="auto")
    assert auto.backend == "cpu"
    assert auto.fallback_reason == ("the GPU extra is not installed (a rig needs it: pip "
                                    "install 'fovexp[gpu]')")


def test_no_moderngl_the_runner_says_only_that_the_cpu_is_used(monkeypatch):
    """The render thread, given the window's GL context to share, does not try it without
    moderngl: its one note is the fallback's, nothing about a GL context (issue 21)."""
    from fovexp import load_display
    from fovexp.experiment.display.render import TestRenderer

    class Share:  # the window's side: never made current without moderngl
        def make_current(self):
            raise AssertionError("no GL context to share without moderngl")

        def release_current(self):
            pass

    _without(monkeypatch, "moderngl")
    r = TestRenderer(load_display("lg-oled55cx"), backend="auto", gl_share=Share())
    try:
        info = r.info()
    finally:
        r.close()
    assert info["backend"] == "cpu" and info["notes"] == []
    assert "fovexp[gpu]" in info["fallback"] and "GL context" not in info["fallback"]


def test_no_tobii_sdk_names_the_tracker_extra(monkeypatch):
    from fovexp.experiment.trackers.tobii import import_tobii

    _without(monkeypatch, "tobii_research")
    with pytest.raises(FovexpError, match=r"pip install 'fovexp\[tracker\]'"):
        import_tobii()


def test_no_web_server_names_the_monitor_extra(monkeypatch):
    """``fovexp monitor`` and ``fovexp run --monitor`` without starlette or uvicorn."""
    from fovexp.monitor.cli import require_server

    for name in ("starlette", "uvicorn"):
        with monkeypatch.context() as m:
            _without(m, name)
            with pytest.raises(FovexpError) as exc:
                require_server()
            msg = str(exc.value)
            assert "pip install 'fovexp[monitor]'" in msg and name in msg and "\n" not in msg


def test_run_with_the_monitor_but_no_web_server_opens_nothing(monkeypatch, tmp_path, capsys):
    from fovexp.cli import build_parser

    _without(monkeypatch, "uvicorn")
    args = build_parser().parse_args(["run", "calibration-fe", "--participant", "M01",
                                      "--dry-run", "--results", str(tmp_path / "results"),
                                      "--monitor"])
    assert args.func(args) == 2
    err = capsys.readouterr().err
    assert "pip install 'fovexp[monitor]'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "results").exists()  # nothing written, no window
