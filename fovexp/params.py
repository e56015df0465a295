"""Method parameters, the paper's Table 2, and the two presets (paper, release).

The calibrated parameters (f_e, s_k, s_f) depend on the foveation strength only (paper
section 5); Table 2 gives them at three blur-rates. :class:`ParameterTable` interpolates them
linearly in blur-rate and clamps outside the table's range. A lab's own calibration (written by
``fovexp analyze``) is a table in the same YAML format::

    source: "Tariq et al. 2022, Table 2"
    rows:
      - {blur_rate: 0.11, f_e: 0.15, s_k: 22.4, s_f: 3.45}
      - ...
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from .config import read_yaml
from .errors import FovexpError, validation_error
from .geometry import GeometryModel

Method = Literal["foveated", "contrast", "ours"]
#: Where the clipping control takes N_min and N_max (section 4.2; fovexp.amplitude).
ClippingRule = Literal["paper", "widened", "release", "exact", "off"]
PresetName = Literal["paper", "release"]

METHODS: tuple[str, ...] = ("foveated", "contrast", "ours")


@dataclass(frozen=True)
class Preset:
    """Constants that differ between the paper and the authors' released prototype."""

    name: str
    #: radius of the full-resolution fovea (paper section 5.2: 8 deg; release: 12 deg)
    fovea_deg: float
    geometry: GeometryModel
    #: attenuation cut-off a of the amplitude level selection (paper section 4.2)
    attenuation: float
    #: Gabor kernel frequency width a, cycles/px (paper section 4.4: 0.06; release: 0.08)
    gabor_a_cpp: float
    #: where the clipping control takes its extremes (section 4.2; fovexp.amplitude's
    #: CLIPPING_RULES), the min/max pyramids' level and the release's box
    clipping: ClippingRule
    minmax_level: int
    minmax_box_px: int
    #: per-impulse exact truncated draw (paper) or the release's rejection with fallback
    frequency_draw: Literal["truncated", "release-rejection"]
    #: colour transfer: pure power law with the display's gamma, or the release's hybrid
    transfer: Literal["power", "release"]


PAPER = Preset(
    name="paper", fovea_deg=8.0, geometry="exact", attenuation=0.25, gabor_a_cpp=0.06,
    clipping="paper", minmax_level=3, minmax_box_px=25, frequency_draw="truncated",
    transfer="power",
)
RELEASE = Preset(
    name="release", fovea_deg=12.0, geometry="release", attenuation=0.1, gabor_a_cpp=0.08,
    clipping="release", minmax_level=3, minmax_box_px=25, frequency_draw="release-rejection",
    transfer="release",
)
PRESETS: dict[str, Preset] = {"paper": PAPER, "release": RELEASE}


def get_preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        raise FovexpError(f"unknown preset {name!r} (choose from {', '.join(PRESETS)})") from None


class EngineOptions(BaseModel):
    """How the engine computes the method, not what the method is: implementation choices
    that trade run time against accuracy, and the exact counterparts the fast choices are
    measured against. The defaults are the enhancer as the paper describes it and this
    package runs it; an enhancer keeps its options for life (``Enhancer(..., options=...)``).

    ``skip``
        Leave out work whose result is known: impulses whose band is empty (F_L >= F_H,
        section 4.1) and impulses, tiles of |L| (section 4.2) and of the contrast change whose
        neighbourhood is flat (constant luminance: |L| and the change are exactly 0 there), and
        tiles of the foveation whose input is constant. Exact by construction: the output is
        bit for bit the same with ``skip=False`` (the no-skip switch, tested).
    ``foveation``
        ``"pyramid"``: the blur stack (:func:`fovexp.foveation.foveate`); ``"exact"``: the
        per-pixel spatially varying convolution (:func:`fovexp.foveation.foveate_exact`,
        slow: the reference).
    ``clipping``
        Where the clipping control takes N_min and N_max (section 4.2;
        :mod:`fovexp.amplitude`, benchmarks/CLIPPING.md): ``None`` (default), the preset's
        rule; ``"paper"``, one level-3 min/max block of luminance; ``"widened"``, every
        level-3 block the kernel reaches, over the channels; ``"release"``, the release's
        25 x 25 box of grey; ``"exact"``, the true extremes over the channels of the pixels
        each impulse's kernel covers; ``"off"``, none (K uncapped: a reference).
    ``dtype``
        Floating-point type of every image stage (``"float64"``: the reference; the result's
        arrays then are float64 too).
    ``kernel_truncation``
        Envelope value at which the Gabor kernel is cut (section 4.4; docs/METHOD.md, 4: 0.01,
        radius 20.2 px at a = 0.06). The impulse cells keep the 0.01 radius, so the impulses stay
        the same whatever the truncation.
    ``impulse_count``
        Impulses per cell: ``"poisson"`` (Lagae et al. 2009, the release) or ``"jittered"``:
        floor(m) or floor(m) + 1 with probability frac(m), mean m = N / pi cell areas the
        same (the noise's variance depends only on the density: its std stays K / 6).
    ``weights``
        Impulse weights: ``"uniform"`` in (-1, 1) (E[w^2] = 1/3), or ``"sign"``: +-1
        (E[w^2] = 1); the normalisation follows E[w^2], so the noise's std stays K / 6.
    ``cell_scale``
        Side of the impulse cells as a fraction of the kernel radius (1: Lagae et al.'s cell);
        smaller cells at the same density let the synthesis cull more finely.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    skip: bool = True
    foveation: Literal["pyramid", "exact"] = "pyramid"
    clipping: ClippingRule | None = None
    dtype: Literal["float32", "float64"] = "float32"
    kernel_truncation: float = Field(default=0.01, ge=1e-6, le=0.5)
    impulse_count: Literal["poisson", "jittered"] = "poisson"
    weights: Literal["uniform", "sign"] = "uniform"
    cell_scale: float = Field(default=1.0, ge=0.25, le=1.0)

    def non_default(self) -> dict[str, object]:
        """The options that differ from the defaults, by name."""
        default = EngineOptions()
        return {k: v for k, v in self.model_dump().items() if getattr(default, k) != v}


def make_options(**kwargs: object) -> EngineOptions:
    """Build :class:`EngineOptions`, turning validation errors into one clear line.

    >>> from fovexp import EngineOptions, make_options
    >>> EngineOptions(skip=False, dtype="float64").non_default()
    {'skip': False, 'dtype': 'float64'}
    >>> make_options(foveation="exact").foveation
    'exact'
    >>> make_options(dtype="float16")
    Traceback (most recent call last):
    fovexp.errors.FovexpError: engine option: dtype='float16': Input should be 'float32' or ...
    """
    try:
        return EngineOptions(**kwargs)
    except ValidationError as exc:
        raise validation_error("engine option", exc) from None


#: Accepted ranges, one definition for every place a parameter is read (CLI, tables, protocols):
#: blur-rate in arcmin/deg, f_e, s_k, s_f unitless; wide enough for any calibration, narrow
#: enough to catch a unit mistake.
BLUR_RATE_RANGE = (0.0, 5.0)
F_E_RANGE = (0.0, 2.0)
S_K_RANGE = (0.0, 200.0)
S_F_RANGE = (0.0, 50.0)  # open at 0: the log-normal needs a width
PARAMETER_RANGES: dict[str, tuple[float, float]] = {
    "blur_rate": BLUR_RATE_RANGE, "f_e": F_E_RANGE, "s_k": S_K_RANGE, "s_f": S_F_RANGE,
}
IMPULSES_RANGE = (1, 512)  # impulses per kernel
SEED_RANGE = (0, 2**31 - 1)
#: What :func:`check_parameter` checks: (lo, hi, open at lo, integer, unit).
_CHECKS: dict[str, tuple[float, float, bool, bool, str]] = {
    "blur_rate": (*BLUR_RATE_RANGE, False, False, " arcmin/deg"),
    "f_e": (*F_E_RANGE, False, False, ""),
    "s_k": (*S_K_RANGE, False, False, ""),
    "s_f": (*S_F_RANGE, True, False, ""),
    "impulses": (*IMPULSES_RANGE, False, True, " per kernel"),
    "seed": (*SEED_RANGE, False, True, ""),
}


def check_parameter(name: str, value: object) -> float | int:
    """``value`` as the number parameter ``name`` takes, if it is one within the accepted range;
    else ``ValueError`` whose message names the range (NaN and Inf are refused, not compared)."""
    lo, hi, open_lo, integer, unit = _CHECKS[name]
    what = "an integer" if integer else "a finite number"
    where = f"{'(' if open_lo else '['}{lo:g}, {hi:g}]{unit}" if not integer else (
        f"[{int(lo)}, {int(hi)}]{unit}")
    try:
        if isinstance(value, bool) or (integer and isinstance(value, float)
                                       and not value.is_integer()):
            raise TypeError
        number: Any = value  # checked by int() / float() themselves
        v = int(number) if integer else float(number)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"must be {what} in {where}") from None
    if not math.isfinite(v) or not (lo < v if open_lo else lo <= v) or v > hi:
        raise ValueError(f"must be {what} in {where}")
    return v + 0  # -0.0 + 0 is +0.0: a negative zero is 0, the same value for every stage


class _CheckedParameters(BaseModel):
    """Range checks of the parameters a model has, before pydantic's own parsing, so that a
    bad value is reported with the accepted range (NaN too, which fails no comparison)."""

    @field_validator("*", mode="before")
    @classmethod
    def _in_range(cls, value: object, info: ValidationInfo) -> object:
        if info.field_name in _CHECKS and value is not None:
            return check_parameter(info.field_name, value)
        return value


def _blur_rate(**kw: Any) -> float:
    return Field(ge=BLUR_RATE_RANGE[0], le=BLUR_RATE_RANGE[1], **kw)


def _f_e(**kw: Any) -> float:
    return Field(ge=F_E_RANGE[0], le=F_E_RANGE[1], **kw)


def _s_k(**kw: Any) -> float:
    return Field(ge=S_K_RANGE[0], le=S_K_RANGE[1], **kw)


def _s_f(**kw: Any) -> float:
    return Field(gt=S_F_RANGE[0], le=S_F_RANGE[1], **kw)


class TableRow(_CheckedParameters):
    model_config = ConfigDict(extra="forbid")
    blur_rate: float = _blur_rate()
    f_e: float = _f_e()
    s_k: float = _s_k()
    s_f: float = _s_f()


class ParameterTable(BaseModel):
    """Calibrated (f_e, s_k, s_f) per blur-rate, interpolated linearly in blur-rate."""

    model_config = ConfigDict(extra="forbid")
    source: str = ""
    rows: list[TableRow] = Field(min_length=1)

    @model_validator(mode="after")
    def _sorted_unique(self) -> ParameterTable:
        rates = [r.blur_rate for r in self.rows]
        if len(set(rates)) != len(rates):
            raise ValueError("blur_rate values must be distinct")
        self.rows.sort(key=lambda r: r.blur_rate)
        return self

    def at(self, blur_rate: float) -> tuple[float, float, float]:
        """(f_e, s_k, s_f) at ``blur_rate``: linear in blur-rate, clamped outside the table."""
        x = [r.blur_rate for r in self.rows]
        return tuple(  # type: ignore[return-value]
            float(np.interp(blur_rate, x, [getattr(r, k) for r in self.rows]))
            for k in ("f_e", "s_k", "s_f")
        )

    @classmethod
    def load(cls, path: str | Path) -> ParameterTable:
        path = Path(path)
        data = read_yaml(path, "parameter table")
        if not isinstance(data, dict):
            raise FovexpError(f"parameter table {path} must be a mapping of keys")
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise validation_error(f"parameter table {path}", exc) from None

    def save(self, path: str | Path) -> None:
        rows = [r.model_dump() for r in self.rows]
        text = yaml.safe_dump({"source": self.source, "rows": rows}, sort_keys=False)
        Path(path).write_text(text)


#: Table 2 of the paper (section 5.3).
PAPER_TABLE2 = ParameterTable(
    source="Tariq, Tursun, Didyk 2022, Table 2",
    rows=[
        TableRow(blur_rate=0.11, f_e=0.15, s_k=22.4, s_f=3.45),
        TableRow(blur_rate=0.34, f_e=0.23, s_k=21.02, s_f=2.21),
        TableRow(blur_rate=0.57, f_e=0.28, s_k=18.68, s_f=2.19),
    ],
)

#: The release's defaults (docs/METHOD.md, 5), one row: the same at every blur-rate.
RELEASE_TABLE = ParameterTable(
    source="released prototype defaults",
    rows=[TableRow(blur_rate=0.0, f_e=0.2, s_k=16.0, s_f=2.1)],
)


class EnhanceParams(_CheckedParameters):
    """Everything that selects what the enhancer computes for one frame.

    ``f_e``, ``s_k`` and ``s_f`` left as ``None`` are taken from the preset's table at
    ``blur_rate`` (see :meth:`resolved`).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    method: Method = "ours"
    blur_rate: float = _blur_rate(default=0.34)  # arcmin per deg past the fovea
    f_e: float | None = _f_e(default=None)
    s_k: float | None = _s_k(default=None)
    s_f: float | None = _s_f(default=None)
    impulses: int = Field(default=64, ge=IMPULSES_RANGE[0], le=IMPULSES_RANGE[1])
    seed: int = Field(default=1, ge=SEED_RANGE[0], le=SEED_RANGE[1])
    preset: PresetName = "paper"

    def resolved(self, table: ParameterTable | None = None) -> EnhanceParams:
        """A copy with f_e, s_k, s_f filled in from ``table`` (default: the preset's)."""
        if table is None:
            table = PAPER_TABLE2 if self.preset == "paper" else RELEASE_TABLE
        f_e, s_k, s_f = table.at(self.blur_rate)
        return self.model_copy(
            update={
                "f_e": f_e if self.f_e is None else self.f_e,
                "s_k": s_k if self.s_k is None else self.s_k,
                "s_f": s_f if self.s_f is None else self.s_f,
            }
        )


def make_params(**kwargs: object) -> EnhanceParams:
    """Build :class:`EnhanceParams`, turning validation errors into one clear line.

    >>> from fovexp import make_params
    >>> p = make_params(blur_rate=0.34, impulses=12)
    >>> p.method, p.blur_rate, p.impulses, p.s_k
    ('ours', 0.34, 12, None)
    >>> r = p.resolved()  # f_e, s_k, s_f from Table 2 at this blur-rate
    >>> r.f_e, r.s_k, r.s_f
    (0.23, 21.02, 2.21)
    >>> make_params(blur_rate=float("nan"))
    Traceback (most recent call last):
    fovexp.errors.FovexpError: parameter: blur_rate=nan: must be a finite number in [0, 5] ...
    """
    try:
        return EnhanceParams(**kwargs)
    except ValidationError as exc:
        raise validation_error("parameter", exc) from None
