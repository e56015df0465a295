"""Experiment protocols: YAML files validated before any window opens.

A protocol describes one of the paper's adjustment experiments (section 5.2 "Experiment
Procedure" for ``calibration-fe``, ``calibration-sk``, ``calibration-sf``; section 6.1 for
``validation``): which parameter the wheel adjusts, its range, steps and start value, the
conditions (images x blur-rates x methods x s_f values) and their repetitions, the seeded
randomised order, the display profile, and where the parameters that are not adjusted come from
(a constant, a condition, Table 2, or an earlier experiment's results folder).

Relative results folders (``fe_results``, ``sk_line_results``, a ``table`` folder) are taken in
the results root the session writes to; every other relative path (display, stimuli, a table
YAML) is relative to the protocol file's folder.

Images are named by id (:mod:`.stimuli`); loading checks that every id is known, and
:meth:`LoadedProtocol.prepare_images` (the CLI right after loading, a :class:`Session` when it is
created; both before any window) checks every file's sha256 and its size for the frame size
the session shows.
"""

from __future__ import annotations

import hashlib
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from fovexp import (
    PARAMETER_RANGES,
    FovexpError,
    check_parameter,
    make_params,
    parse_yaml,
    validation_error,
)
from fovexp.results.blanking import BLANKING_RADIUS_DEG, GAZE_TIMEOUT_S
from fovexp.stimuli.folder import ImageCheck, Size, StimulusSet, may_scale

from .defaults import (
    MAX_ACCURACY_DEG,
    MAX_DATA_LOSS,
    TRACKER_RATE_HZ,
    QualityLimits,
    central_accuracy_limit_deg,
)
from .forced_choice import ForcedChoiceSpec, derived_adjust, forced_choice_plan

Parameter = Literal["f_e", "s_k", "s_f", "blur_rate"]
MethodName = Literal["foveated", "contrast", "ours"]

#: A wheel step's render may take this long before the runner warns (ms): 12 frames at 120 Hz
#: (this project's choice; the paper says only that the test half updated "in real-time").
DEFAULT_MAX_STEP_MS = 100.0

def check_in_range(name: str, value: float) -> str | None:
    """Why ``value`` is outside what the enhancer accepts for ``name`` (None: it is inside):
    the enhancer's own check (:func:`fovexp.check_parameter`), worded for a protocol file."""
    try:
        check_parameter(name, value)
    except ValueError as exc:
        return f"{value} is outside what {name} allows: {exc}"
    return None


#: Parameters each method uses besides the blur-rate (paper sections 5, 6.2).
METHOD_NEEDS: dict[str, tuple[str, ...]] = {
    "foveated": (),
    "contrast": ("f_e",),
    "ours": ("f_e", "s_k", "s_f"),
}
PAPER_TABLE_NAMES = ("paper-table2", "table2")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class AdjustSpec(_Strict):
    """The adjusted parameter: range, a coarse and a fine step per wheel notch, start value."""

    parameter: Parameter
    range: tuple[float, float]
    step: float = Field(gt=0)
    fine_step: float = Field(gt=0)
    #: a fixed value, or ``random`` (uniform in the range, from the session seed)
    start: float | Literal["random"] = "random"

    @model_validator(mode="after")
    def _check(self) -> AdjustSpec:
        lo, hi = self.range
        if not lo < hi:
            raise ValueError(f"range [{lo}, {hi}] must have low < high")
        for end in (lo, hi):
            why = check_in_range(self.parameter, end)
            if why is not None:
                raise ValueError(f"range [{lo}, {hi}]: {why}")
        if self.fine_step > self.step:
            raise ValueError("fine_step must not exceed step")
        if self.step > hi - lo:
            raise ValueError(f"step {self.step} is larger than the range {hi - lo}")
        if isinstance(self.start, float) and not lo <= self.start <= hi:
            raise ValueError(f"start {self.start} is outside the range [{lo}, {hi}]")
        return self


class ParamSource(_Strict):
    """Where a parameter that is not adjusted comes from; exactly one key is set.

    ``value``: a constant. ``condition``: the trial's condition (``s_f_values``).
    ``table``: ``paper-table2``, a ParameterTable YAML (``.yaml``/``.yml``, relative to the
    protocol file), or a results folder holding ``calibration-fe/-sk/-sf``
    (``fovexp.results.derive.parameter_table``; ``.`` is the results root itself), interpolated by
    blur-rate. ``fe_results``: a calibration-fe results folder (``fe_by_blur_rate``).
    ``sk_line_results``: a calibration-sk results folder; s_k = slope * s_f + intercept per
    blur-rate (``sk_line_by_blur_rate``). Relative results folders are taken in the results root
    the session writes to (``fovexp run --results``, default ``./results``), so a chain of
    experiments always reads its own earlier results, wherever they are kept.
    """

    value: float | None = None
    condition: bool = False
    table: str | None = None
    fe_results: str | None = None
    sk_line_results: str | None = None

    @model_validator(mode="after")
    def _one(self) -> ParamSource:
        n = sum(
            x is not None for x in (self.value, self.table, self.fe_results, self.sk_line_results)
        ) + int(self.condition)
        if n != 1:
            raise ValueError(
                "exactly one of value, condition, table, fe_results, sk_line_results must be set"
            )
        return self


class FixationSpec(_Strict):
    #: gaze farther than this from the cross blanks the next frame (paper section 5.1: 1.25 deg)
    radius_deg: float = Field(default=BLANKING_RADIUS_DEG, gt=0, le=20)
    cross_size_deg: float = Field(default=0.6, gt=0, le=10)
    #: gaze older than this counts as lost (s)
    gaze_timeout_s: float = Field(default=GAZE_TIMEOUT_S, gt=0, le=2)


class TrackerSpec(_Strict):
    """Tracker settings and the validation's limits (:mod:`fovexp.experiment.protocol.defaults`;
    checked by :mod:`fovexp.experiment.trackers.quality`)."""

    sampling_hz: float = Field(default=TRACKER_RATE_HZ, gt=0, le=2000)
    #: refuse to start when the worse eye's accuracy at the central target exceeds this (deg);
    #: default ``CENTRAL_ACCURACY_FRACTION`` (0.4) x ``fixation.radius_deg``; below the radius
    max_central_accuracy_deg: float | None = Field(default=None, gt=0, le=10)
    #: ... or its accuracy averaged over the validation targets (deg)
    max_accuracy_deg: float = Field(default=MAX_ACCURACY_DEG, gt=0, le=10)
    #: ... or when either eye lost more than this fraction of the samples expected (rate x time)
    max_data_loss: float = Field(default=MAX_DATA_LOSS, ge=0, le=1)
    calibration_points: Literal[5, 9] = 9
    validation_points: int = Field(default=5, ge=1, le=13)
    #: a drift check after every this many main trials (0: only when the operator presses D)
    drift_check_every: int = Field(default=0, ge=0)
    #: a drift check fails above this offset at the centre (deg); default the central limit
    max_drift_deg: float | None = Field(default=None, gt=0, le=10)
    #: ``--tracker iohub``'s configuration (the YAML PsychoPy Builder or ioHub uses), relative
    #: to this file; ``--tracker-config`` overrides it
    iohub_config: str | None = None


class RenderSpec(_Strict):
    #: the frame budget of a wheel step: the longest a step's render may take (ms) before the
    #: runner warns at the start (it measures one on the chosen backend); the paper updated the
    #: test half "in real-time" (section 5.1)
    max_step_ms: float = Field(default=DEFAULT_MAX_STEP_MS, gt=0, le=60_000)


class Protocol(_Strict):
    """A whole experiment (see the module docstring)."""

    experiment: str = Field(pattern=r"^[a-z0-9][a-z0-9_-]{0,40}$")
    title: str = ""
    paper_section: str = ""
    display: str
    #: default: the preset's (exact for paper, release for release)
    geometry: Literal["exact", "linear", "release"] | None = None
    preset: Literal["paper", "release"] = "paper"
    #: the stimulus folder (or its manifest.yaml), relative to this file; default: found as
    #: :func:`fovexp.stimuli.folder.find_folder` says (``--stimuli``, $FOVEXP_STIMULI,
    #: ./stimuli, the user data folder)
    stimuli: str | None = None
    images: list[str] = Field(min_length=1)
    methods: list[MethodName] = Field(min_length=1)
    blur_rates: list[float] | None = None
    s_f_values: list[float] | None = None
    adjust: AdjustSpec
    #: the participant's task: ``adjust`` (the paper's, section 5.1) or ``2afc`` (two-alternative
    #: forced choice, issue 30: the ``forced_choice`` block; ``adjust`` is then derived from it)
    task: Literal["adjust", "2afc"] = "adjust"
    forced_choice: ForcedChoiceSpec | None = None
    parameters: dict[Literal["f_e", "s_k", "s_f"], ParamSource] = Field(default_factory=dict)
    repetitions: int = Field(default=1, ge=1, le=100)
    seed: int = Field(ge=0, le=2**31 - 1)
    practice_trials: int = Field(default=2, ge=0, le=50)
    #: methods of the practice trials (default: ``methods``). Paper section 6.1 practised on a
    #: foveation method other than the evaluated ones, so as not to bias the participants.
    practice_methods: list[MethodName] | None = Field(default=None, min_length=1)
    break_every: int = Field(default=0, ge=0)
    impulses: int = Field(default=64, ge=1, le=512)
    fixation: FixationSpec = FixationSpec()
    tracker: TrackerSpec = TrackerSpec()
    render: RenderSpec = RenderSpec()
    instructions: str = ""

    @property
    def geometry_model(self) -> str:
        """The geometry the enhancer and the gaze check use."""
        if self.geometry is not None:
            return self.geometry
        return "release" if self.preset == "release" else "exact"

    @property
    def quality_limits(self) -> QualityLimits:
        """The validation's limits, the central one derived from the fixation window unless
        given."""
        t = self.tracker
        central = t.max_central_accuracy_deg
        if central is None:
            central = central_accuracy_limit_deg(self.fixation.radius_deg)
        return QualityLimits(t.max_accuracy_deg, central, t.max_data_loss)

    @property
    def drift_limit_deg(self) -> float:
        """A drift check's limit: ``tracker.max_drift_deg``, else the central accuracy limit."""
        d = self.tracker.max_drift_deg
        return self.quality_limits.max_central_accuracy_deg if d is None else d

    @model_validator(mode="before")
    @classmethod
    def _derived_adjust(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        if (data.get("task") == "2afc") != ("forced_choice" in data):
            raise ValueError("forced_choice: required with task: 2afc, and only with it")
        return derived_adjust(data) if data.get("task") == "2afc" else data

    @model_validator(mode="after")
    def _consistent(self) -> Protocol:
        if (self.task == "2afc") != (self.forced_choice is not None):
            raise ValueError("forced_choice: required with task: 2afc, and only with it")
        if self.task == "2afc" and self.adjust.parameter != "blur_rate":
            raise ValueError("adjust: a task: 2afc protocol shows the blur-rate; leave adjust "
                             "out (it is derived from forced_choice)")
        if self.task == "2afc" and self.s_f_values:
            raise ValueError("s_f_values: not with task: 2afc (its conditions are the methods)")
        radius = self.fixation.radius_deg
        for key in ("max_central_accuracy_deg", "max_drift_deg"):
            v = getattr(self.tracker, key)
            if v is not None and v >= radius:
                raise ValueError(
                    f"tracker.{key}: {v:g} deg is not below fixation.radius_deg {radius:g} deg "
                    "(a tracker that far off at the cross cannot tell gaze inside the window "
                    "from gaze outside it)")
        p = self.adjust.parameter
        if self.preset == "release" and self.geometry not in (None, "release"):
            # The enhancer's release preset always uses the release's own geometry.
            raise ValueError(f"geometry: {self.geometry!r} contradicts preset 'release' (which "
                             "uses the release geometry): leave geometry out or set 'release'")
        if len(set(self.images)) != len(self.images):
            raise ValueError("images: duplicate ids")
        if p == "blur_rate":
            if self.blur_rates:
                raise ValueError("blur_rates: not allowed when the blur-rate is adjusted")
        elif not self.blur_rates:
            raise ValueError("blur_rates: required (one or more) unless adjust.parameter is "
                             "blur_rate")
        for key, name in (("blur_rates", "blur_rate"), ("s_f_values", "s_f")):
            for v in getattr(self, key) or []:
                why = check_in_range(name, v)
                if why is not None:
                    raise ValueError(f"{key}: {why}")
        if p in self.parameters:
            raise ValueError(f"parameters.{p}: {p} is the adjusted parameter")
        every = [*self.methods, *(self.practice_methods or [])]
        needed = {n for m in every for n in METHOD_NEEDS[m]} - {p}
        if p in ("f_e", "s_k", "s_f") and not any(p in METHOD_NEEDS[m] for m in self.methods):
            raise ValueError(f"adjust.parameter: no method in {self.methods} uses {p}")
        for m in self.practice_methods or []:
            if p in ("f_e", "s_k", "s_f") and p not in METHOD_NEEDS[m]:
                raise ValueError(f"practice_methods: {m} does not use the adjusted {p}")
        for n in sorted(needed):
            if n not in self.parameters:
                raise ValueError(f"parameters.{n}: required (methods {every} use it)")
        for n, src in self.parameters.items():
            if src.condition and (n != "s_f" or not self.s_f_values):
                raise ValueError(f"parameters.{n}.condition: only s_f can come from the "
                                 "conditions, and then s_f_values must be given")
            if src.value is not None:
                why = check_in_range(n, src.value)
                if why is not None:
                    raise ValueError(f"parameters.{n}.value: {why}")
            if src.fe_results is not None and n != "f_e":
                raise ValueError(f"parameters.{n}.fe_results: only for f_e")
            if src.sk_line_results is not None and n != "s_k":
                raise ValueError(f"parameters.{n}.sk_line_results: only for s_k")
        if self.s_f_values and not (
            "s_f" in self.parameters and self.parameters["s_f"].condition
        ):
            raise ValueError("s_f_values: given but parameters.s_f is not {condition: true}")
        return self


@dataclass(frozen=True)
class Trial:
    """One trial of a session's plan."""

    index: int
    practice: bool
    repetition: int
    image: str
    method: str
    blur_rate: float | None  # None when the blur-rate is adjusted
    s_f: float | None  # the s_f condition, if any
    start_value: float


@dataclass
class LoadedProtocol:
    """A validated protocol with its resolved files and parameter sources."""

    path: Path
    sha256: str
    text: str
    spec: Protocol
    stimuli: StimulusSet
    display_name: str
    display: Any  # fovexp.Display
    #: functions (blur_rate, s_f or None) -> value, for the parameters that are not adjusted
    sources: dict[str, Callable[[float, float | None], float]] = field(default_factory=dict)
    dependency_folders: dict[str, str] = field(default_factory=dict)
    #: what the sources derive from files (tables, earlier results): JSON data per parameter,
    #: stored in the session file and reused by ``--resume``
    derived: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: the images checked for a frame size (:meth:`prepare_images`)
    images: dict[str, ImageCheck] = field(default_factory=dict)
    _images_for: tuple[Size, bool, bool] | None = None  # frame size, dry run, may scale

    @property
    def native_size(self) -> Size:
        """The display's own resolution: the frame size of a real session."""
        return int(self.display.width_px), int(self.display.height_px)

    def prepare_images(self, frame_size: Size, dry_run: bool) -> dict[str, ImageCheck]:
        """Check every image for frames of ``frame_size``: listed, present, unchanged (sha256)
        and of exactly that size, or (``dry_run`` in a window of another size than the
        display's: :func:`.stimuli.may_scale`) scaled to it. Raises FovexpError naming the
        image, its size and the needed size, with the command that fixes it: at the display's
        own size a dry run refuses exactly what the real session refuses, with the same line."""
        size: Size = (int(frame_size[0]), int(frame_size[1]))
        key = (size, bool(dry_run), may_scale(dry_run, size, self.native_size))
        if self._images_for != key:
            self.images = self.stimuli.require(self.spec.images, size, key[2],
                                               f"protocol {self.path}")
            self._images_for = key
        return self.images

    @property
    def image_paths(self) -> dict[str, Path]:
        """The checked file of each image (after :meth:`prepare_images`)."""
        return {k: v.path for k, v in self.images.items() if v.path is not None}

    def stimuli_record(self) -> dict[str, Any]:
        """What a session file keeps of its images: folder, frame size, each file's sha256 and
        size, and which a dry run scaled."""
        assert self._images_for is not None, "prepare_images first"
        size, dry, scale = self._images_for
        return {"folder": str(self.stimuli.folder), "found_by": self.stimuli.found_by,
                "frame_size": list(size), "dry_run": dry, "may_scale": scale,
                "scaled": sorted(k for k, v in self.images.items() if v.scaled),
                "images": {k: v.record() for k, v in self.images.items()}}

    def use_derived(self, derived: dict[str, dict[str, Any]]) -> None:
        """(Re)build the parameter sources from ``derived`` (this protocol's own, or those a
        session stored at its first start), then check that every trial of the plan gives the
        enhancer parameters it accepts at both ends of the adjusted range."""
        where = f"protocol {self.path}"
        for name, src in self.spec.parameters.items():
            self.sources[name] = _make_source(f"{where}: parameters.{name}", name, src,
                                              derived.get(name), self.spec)
        self.derived = dict(derived)
        s = self.spec
        lo, hi = s.adjust.range
        methods = dict.fromkeys([*s.methods, *(s.practice_methods or [])])
        for method, br, sf in itertools.product(methods, s.blur_rates or [None],
                                                s.s_f_values or [None]):
            trial = Trial(-1, False, 0, s.images[0], method, br, sf, lo)
            for value in (lo, hi):
                try:
                    self.make_params(trial, value, seed=0)
                except FovexpError as exc:
                    cond = ", ".join(f"{k}={v}" for k, v in (("method", method),
                                     ("blur_rate", br), ("s_f", sf)) if v is not None)
                    raise FovexpError(f"{where}: {s.adjust.parameter}={value} ({cond}): "
                                      f"{exc}") from None

    def make_params(self, trial: Trial, value: float, seed: int) -> Any:
        """The enhancer's parameters (``fovexp.make_params``) when the adjusted parameter is
        ``value``; raises FovexpError."""
        vals = self.parameter_values(trial, value)
        s = self.spec
        return make_params(method=trial.method, blur_rate=vals["blur_rate"], f_e=vals["f_e"],
                           s_k=vals["s_k"], s_f=vals["s_f"], impulses=s.impulses, seed=seed,
                           preset=s.preset)

    @property
    def experiment(self) -> str:
        return self.spec.experiment

    def parameter_values(self, trial: Trial, value: float) -> dict[str, float | None]:
        """f_e, s_k, s_f and blur-rate in effect when the adjusted parameter is ``value``."""
        adj = self.spec.adjust.parameter
        out: dict[str, float | None] = {"f_e": None, "s_k": None, "s_f": None,
                                        "blur_rate": trial.blur_rate}
        out[adj] = float(value)
        br = float(out["blur_rate"])  # type: ignore[arg-type]
        needs = METHOD_NEEDS[trial.method]
        # s_f first: an s_k line needs it (section 5.2, "Bandwidth scaling").
        for name in ("s_f", "f_e", "s_k"):
            if name == adj or name not in needs:
                continue
            sf = out["s_f"] if out["s_f"] is not None else trial.s_f
            out[name] = float(self.sources[name](br, sf))
        return out

    def plan(self, participant: str, limit: int | None = None,
             practice: int | None = None) -> tuple[int, list[Trial]]:
        """The session seed and the trial list: practice first, then the randomised conditions.

        The order depends only on the protocol's seed and the participant, so ``--resume``
        regenerates the same plan. ``limit`` keeps the first ``limit`` main trials (pilots,
        tests) with each scene's methods together (:func:`limit_order`), so that a short
        validation still pairs ours with contrast; the kept trials keep their order and their
        start values.
        """
        seed = session_seed(self.spec.seed, participant)
        rng = np.random.default_rng(seed)
        s = self.spec
        if s.forced_choice is not None:  # the blur-rate comes from the procedure at run time
            n = s.practice_trials if practice is None else practice
            top = s.forced_choice.grid.high
            return seed, [Trial(k, p, 0, image, method, None, None, top) for k, (p, method, image)
                          in enumerate(forced_choice_plan(
                              list(s.methods), s.practice_methods, list(s.images),
                              s.forced_choice, seed, n, limit))]
        conds = list(itertools.product(
            range(s.repetitions), s.images, s.blur_rates or [None], s.methods,
            s.s_f_values or [None],
        ))
        order = rng.permutation(len(conds))
        n_practice = s.practice_trials if practice is None else practice
        prng = np.random.default_rng(seed + 1)
        practice_conds = [conds[int(i)] for i in prng.integers(0, len(conds), n_practice)]
        if s.practice_methods:
            pm = s.practice_methods
            practice_conds = [(*c[:3], pm[int(prng.integers(len(pm)))], c[4])
                              for c in practice_conds]
        main = [conds[int(i)] for i in order]
        # positions in the full plan: a trial's start value is drawn from its own stream, so it
        # does not depend on the limit
        positions = list(range(n_practice + len(main)))
        if limit is not None:
            keep = limit_order([(c[0], c[1], c[2], c[4]) for c in main], limit)
            main = [main[i] for i in keep]
            positions = positions[:n_practice] + [n_practice + i for i in keep]
        lo, hi = s.adjust.range
        trials = []
        for k, (cond, is_practice) in enumerate(
            [(c, True) for c in practice_conds] + [(c, False) for c in main]
        ):
            rep, image, br, method, sf = cond
            start = s.adjust.start
            srng = np.random.default_rng([seed, positions[k]])
            start_value = float(srng.uniform(lo, hi)) if start == "random" else float(start)
            trials.append(Trial(k, is_practice, rep if not is_practice else 0, image, method,
                                br, sf, start_value))
        return seed, trials


def limit_order(groups: list[Any], limit: int) -> list[int]:
    """Which of a randomised order's trials a ``--limit-trials`` of ``limit`` keeps, in order:
    whole groups (``groups[i]`` is trial i's condition without its method: repetition, image,
    blur-rate, s_f), taken in the order their first trial comes, until ``limit`` trials are
    kept (the last group whole: ``limit`` rounded up). A group's methods are what the validation
    pairs (ours against contrast on the same scene, section 6.1), so a short pilot still
    pairs; with one method per group it is the first ``limit`` trials.

    >>> limit_order(["a", "b", "a", "c", "b", "c"], 2)
    [0, 2]
    >>> limit_order(["a", "b", "a", "c", "b", "c"], 3)
    [0, 1, 2, 4]
    >>> limit_order(["a", "b", "c"], 2)
    [0, 1]
    """
    chosen: set[Any] = set()
    size: dict[Any, int] = {}
    for g in groups:
        size[g] = size.get(g, 0) + 1
    n = 0
    for g in groups:
        if n >= limit:
            break
        if g not in chosen:
            chosen.add(g)
            n += size[g]
    return [i for i, g in enumerate(groups) if g in chosen]


def session_seed(protocol_seed: int, participant: str) -> int:
    """Per-participant seed for the order, start values and noise (logged in ``seed``)."""
    h = hashlib.sha256(f"{protocol_seed}:{participant}".encode()).digest()
    return int.from_bytes(h[:4], "little") & 0x7FFFFFFF


def _resolve_path(base: Path, rel: str) -> Path:
    p = Path(rel).expanduser()
    return p if p.is_absolute() else (base / p).resolve()


def read_protocol(path: str | Path) -> tuple[bytes, Protocol]:
    """A protocol file's bytes and its validated content (no file it names is opened)."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise FovexpError(f"cannot read protocol {path}: {exc.strerror}") from None
    text = raw.decode("utf-8", errors="replace")
    data = parse_yaml(text, f"protocol {path}")
    if not isinstance(data, dict):
        raise FovexpError(f"protocol {path} must be a mapping of keys")
    try:
        return raw, Protocol.model_validate(data)
    except ValidationError as exc:
        raise validation_error(f"protocol {path}", exc) from None


def protocol_display(path: Path, spec: Protocol) -> tuple[str, Any]:
    """The display profile a protocol names: a YAML path relative to the protocol file, or a
    profile's name (``lg-oled55cx``), looked up in ``displays/`` beside the protocol file (a
    study folder's own profiles, wherever it is run from), then where
    :func:`fovexp.load_display` looks (``./protocols/displays``, the shipped profiles)."""
    from fovexp import load_display

    disp = spec.display
    beside = path.resolve().parent / "displays" / f"{disp}.yaml"
    if disp.endswith((".yaml", ".yml")):
        disp = str(_resolve_path(path.resolve().parent, disp))
    elif "/" not in disp and beside.is_file():
        disp = str(beside)
    try:
        return disp, load_display(disp)
    except FovexpError as exc:
        raise FovexpError(f"protocol {path}: display: {exc}") from None


def protocol_stimuli(path: Path, spec: Protocol,
                     stimuli: str | Path | None = None) -> StimulusSet:
    """The stimulus set of a protocol: ``stimuli`` (``--stimuli``) or the folder the protocol
    names or the default one (:func:`fovexp.stimuli.folder.find_folder`)."""
    try:
        return StimulusSet.find(stimuli, spec.stimuli, path.resolve().parent)
    except FovexpError as exc:
        raise FovexpError(f"protocol {path}: stimuli: {exc}") from None


def load_protocol(path: str | Path, check_dependencies: bool = True,
                  results_root: str | Path = "results", real_only: bool = False,
                  stimuli: str | Path | None = None,
                  include_pilots: bool = False) -> LoadedProtocol:
    """Load and validate a protocol, its images and its dependencies, before any window opens.

    Dependency folders are looked up under ``results_root`` (where the session writes; see
    :class:`ParamSource`). ``real_only`` (a session with a participant, not a dry run) refuses a
    dependency holding only simulated sessions; ``include_pilots`` lets the dependencies'
    mouse-gaze pilot sessions count (left out by default, as in the analysis). ``stimuli``: the
    stimulus folder (``--stimuli``; default: the protocol's ``stimuli`` key, else
    :func:`.stimuli.find_folder`). Raises :class:`FovexpError` naming the file and the key for
    an unknown key, an out-of-range value, an image id that is neither a generated scene nor in
    the stimulus folder's manifest, or a missing dependency folder. The image files are checked
    by :meth:`~LoadedProtocol.prepare_images`, for the frame size the session shows.
    """
    path = Path(path)
    raw, spec = read_protocol(path)
    text = raw.decode("utf-8", errors="replace")
    base = path.resolve().parent
    disp, display = protocol_display(path, spec)
    stim = protocol_stimuli(path, spec, stimuli)
    for i, img in enumerate(spec.images):
        if img not in stim:
            unknown = stim.check(img, (0, 0), dry_run=True).problem
            raise FovexpError(f"protocol {path}: images[{i}]: {unknown}")
    lp = LoadedProtocol(path=path, sha256=hashlib.sha256(raw).hexdigest(), text=text, spec=spec,
                        stimuli=stim, display_name=disp, display=display)
    deps = _Dependencies(base, Path(results_root), check_dependencies, real_only,
                         include_pilots)
    for name, src in spec.parameters.items():
        snap = _snapshot(path, deps, name, src, lp)
        if snap is not None:
            lp.derived[name] = snap
    lp.use_derived(lp.derived)
    return lp


def _interp(where: str, pairs: list[list[float]], needed: list[float]) -> Callable[[float], float]:
    xs = [float(x) for x, _ in sorted(pairs)]
    ys = [float(y) for _, y in sorted(pairs)]
    for br in needed:
        # Calibration dependencies must cover the blur-rates asked for; no extrapolation.
        if br < xs[0] - 1e-9 or br > xs[-1] + 1e-9:
            raise FovexpError(f"{where}: results cover blur-rates {xs}, not {br}")
    return lambda br: float(np.interp(br, xs, ys))


def _results_path(where: str, results_root: Path, rel: str) -> Path:
    """A results folder named in a protocol: relative ones lie inside the results root.

    A relative path climbing out of it (``../results/calibration-fe``, as protocols named them
    when paths were relative to the protocol file) would read another study's folder under
    ``--results /data/study``: it is refused, not guessed."""
    p = Path(rel).expanduser()
    if not p.is_absolute() and ".." in p.parts:
        raise FovexpError(f"{where}: {rel!r} leaves the results root {results_root}: name the "
                          "experiment's folder in it (e.g. calibration-fe, or . for the root) "
                          "or give an absolute path")
    return _resolve_path(results_root, rel)


@dataclass(frozen=True)
class _Dependencies:
    """Where a protocol's dependencies are found, and how strictly they are checked."""

    protocol_dir: Path  # table YAML files
    results_root: Path  # results folders
    check: bool
    real_only: bool
    include_pilots: bool = False


def _snapshot(path: Path, deps: _Dependencies, name: str, src: ParamSource,
              lp: LoadedProtocol) -> dict[str, Any] | None:
    """The values a parameter source derives from files (a table, earlier results), as JSON
    data; None for a constant or a condition. Stored in the session file at the first start so
    that ``--resume`` uses the same values even when the results folders changed since."""
    where = f"protocol {path}: parameters.{name}"
    if src.table is not None:
        if src.table in PAPER_TABLE_NAMES:
            from fovexp import PAPER_TABLE2
            table = PAPER_TABLE2
        elif src.table.endswith((".yaml", ".yml")):
            from fovexp import ParameterTable

            tpath = _resolve_path(deps.protocol_dir, src.table)
            lp.dependency_folders[name] = str(tpath)
            if not tpath.is_file():
                raise FovexpError(f"{where}.table: parameter table {tpath} does not exist")
            try:
                table = ParameterTable.load(tpath)
            except FovexpError as exc:
                raise FovexpError(f"{where}.table: {exc}") from None
        else:
            tpath = _results_path(f"{where}.table", deps.results_root, src.table)
            lp.dependency_folders[name] = str(tpath)
            _require_results(where + ".table", tpath, deps.check, nested=True)
            from fovexp.results.derive import parameter_table
            table = _call(where + ".table", lambda f: parameter_table(
                f, real_only=deps.real_only, include_pilots=deps.include_pilots), tpath)
        return {"kind": "table", "from": src.table, "table": table.model_dump()}
    # values derived from an earlier experiment's results folder (section 5.2's chain)
    derived = (
        ("fe_results", "fe_by_blur_rate",
         lambda fe: {"f_e": [[float(b), float(v)] for b, v in sorted(fe.items())]}),
        ("sk_line_results", "sk_line_by_blur_rate",
         lambda lines: {"slope_intercept": [[float(b), float(v[0]), float(v[1])]
                                            for b, v in sorted(lines.items())]}),
    )
    for key, fn_name, pack in derived:
        rel = getattr(src, key)
        if rel is None:
            continue
        folder = _results_path(f"{where}.{key}", deps.results_root, rel)
        lp.dependency_folders[name] = str(folder)
        _require_results(f"{where}.{key}", folder, deps.check)
        from fovexp.results import derive
        fn = getattr(derive, fn_name)
        values = _call(f"{where}.{key}", lambda f, fn=fn: fn(f, real_only=deps.real_only,
                                                             include_pilots=deps.include_pilots),
                       folder)
        return {"kind": key, "from": str(folder), **pack(values)}
    return None


def _make_source(where: str, name: str, src: ParamSource, snap: dict[str, Any] | None,
                 spec: Protocol) -> Callable[[float, float | None], float]:
    """The function (blur_rate, s_f) -> value of a parameter that is not adjusted."""
    if src.value is not None:
        v = float(src.value)
        return lambda br, sf: v
    if src.condition:
        def from_condition(br: float, sf: float | None) -> float:
            assert sf is not None
            return float(sf)
        return from_condition
    assert snap is not None
    needed = list(spec.blur_rates or [])
    if snap["kind"] == "table":
        from fovexp import ParameterTable

        table = ParameterTable.model_validate(snap["table"])
        k = ("f_e", "s_k", "s_f").index(name)
        return lambda br, sf: table.at(br)[k]
    if snap["kind"] == "fe_results":
        f = _interp(where + ".fe_results", snap["f_e"], needed)
        return lambda br, sf: f(br)
    rows = snap["slope_intercept"]
    slope = _interp(where + ".sk_line_results", [[b, m] for b, m, _ in rows], needed)
    icpt = _interp(where + ".sk_line_results", [[b, c] for b, _, c in rows], needed)

    def sk_line(br: float, sf: float | None) -> float:
        assert sf is not None
        lo, hi = PARAMETER_RANGES["s_k"]
        return float(min(max(slope(br) * sf + icpt(br), lo), hi))

    return sk_line


def _require_results(where: str, folder: Path, check: bool, nested: bool = False) -> None:
    if not folder.is_dir():
        raise FovexpError(f"{where}: results folder {folder} does not exist (run the "
                          "experiment it depends on first, with the same --results, or fix the "
                          "path)")
    pattern = "*/*/trials.csv" if nested else "*/trials.csv"
    if check and not any(folder.glob(pattern)):
        raise FovexpError(f"{where}: results folder {folder} holds no trials.csv")


def _call(where: str, fn: Callable, folder: Path):  # type: ignore[type-arg]
    try:
        out = fn(folder)
    except FovexpError as exc:
        raise FovexpError(f"{where}: {exc}") from None
    if not out:
        raise FovexpError(f"{where}: no usable trials in {folder}")
    if isinstance(out, dict):
        for k, v in out.items():
            vals = v if isinstance(v, tuple) else (v,)
            if not all(math.isfinite(float(x)) for x in vals):
                raise FovexpError(f"{where}: non-finite result at blur-rate {k} in {folder}")
    return out
