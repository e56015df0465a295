"""The runner's protocols (:mod:`fovexp.experiment.interfaces`) are those of the real classes and
of the tests' stand-ins: every method a protocol names exists on each, with the protocol's
parameters in the protocol's order (a renamed or reordered parameter fails here, not in a
session). Checked on the classes: no window, tracker or GL context is opened."""

from __future__ import annotations

import inspect

import pytest

from fovexp.experiment.display.render import TestRenderer
from fovexp.experiment.display.window import PsychoScreen
from fovexp.experiment.interfaces import GazeSource, Renderer, Screen
from fovexp.experiment.trackers.mouse import MouseGaze
from fovexp.experiment.trackers.simulated import SimulatedGaze
from fovexp.experiment.trackers.tobii import TobiiGaze

from experiment_helpers import ScriptedGaze, StubScreen


def members(proto: type) -> dict[str, object]:
    return {k: v for k, v in vars(proto).items()
            if not k.startswith("_") and (callable(v) or isinstance(v, property))}


def mismatches(cls: type, proto: type) -> list[str]:
    out = []
    for name, want in members(proto).items():
        got = inspect.getattr_static(cls, name, None)
        if got is None and isinstance(want, property):
            # an attribute the constructor sets
            sources = [inspect.getsource(c) for c in cls.__mro__ if c is not object]
            if any(f"self.{name} =" in src or f"self.{name}: " in src for src in sources):
                continue
        if got is None:
            out.append(f"{name} missing")
            continue
        if isinstance(want, property):
            continue
        if not callable(got):
            out.append(f"{name} not a method")
            continue
        w = list(inspect.signature(want).parameters)[1:]
        params = list(inspect.signature(got).parameters.values())[1:]
        g = [p.name for p in params]
        # the protocol's parameters first; any more must have defaults
        if g[: len(w)] != w or any(p.default is p.empty and p.kind not in (
                p.VAR_POSITIONAL, p.VAR_KEYWORD) for p in params[len(w):]):
            out.append(f"{name}{tuple(g)} instead of {tuple(w)}")
    return out


@pytest.mark.parametrize("cls", [PsychoScreen, StubScreen])
def test_screens(cls: type) -> None:
    assert mismatches(cls, Screen) == []


@pytest.mark.parametrize("cls", [SimulatedGaze, MouseGaze, TobiiGaze, ScriptedGaze])
def test_gaze_sources(cls: type) -> None:
    assert mismatches(cls, GazeSource) == []


def test_renderer() -> None:
    assert mismatches(TestRenderer, Renderer) == []


def test_the_check_can_fail() -> None:
    class Partial:
        def flip(self, when):  # noqa: ANN001, ANN201
            return 0.0

    got = mismatches(Partial, Screen)
    assert "close missing" in got and any(g.startswith("flip(") for g in got)
