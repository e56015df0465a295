"""Viewing geometry: eccentricity, pixels per degree and frequency-unit conversions.

A display profile (``protocols/displays/*.yaml``) gives the screen's pixel grid, physical size and
viewing distance. An image whose size differs from the display's is shown full screen: the screen's
physical size and distance stay, the pixel pitch scales with the image (a 960x540 image on a 4K
profile is a coarser rendering of the same view).

Three models of the geometry are offered:

``exact``
    Flat screen, eye on the normal through the screen centre. Eccentricity is the true angle
    between the gaze ray and the pixel's ray; pixels per degree grow off-axis (docs/METHOD.md, 4).
``linear``
    The paper's approximation (section 5.1): a constant ``width_px / horizontal field`` pixels
    per degree and eccentricity = on-screen distance / that constant.
``release``
    The authors' released prototype (docs/METHOD.md, 5): eccentricity ``atan(R / D)`` with ``R``
    the physical distance from the gaze point on the screen, and a constant 42.67 px/deg
    (1920 px / 45 deg) at 3840 px width.

Coordinates: pixel centres at integer ``(x, y)``, x to the right, y down; gaze points in
normalised screen coordinates ``(x_h, x_v)`` in [0, 1] (paper section 3).

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numba
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .config import read_yaml
from .errors import FovexpError, validation_error
from .jit import FASTMATH, flat_broadcast, fma
from .resources import shipped_displays

GeometryModel = Literal["exact", "linear", "release"]

#: Minutes of arc per degree of visual angle.
ARCMIN_PER_DEG = 60.0

#: Release constants (docs/METHOD.md, 5): 3840 px over a 90 degree field, taken as constant.
RELEASE_PPD_AT_3840 = 1920.0 / 45.0
RELEASE_WIDTH_CM = 120.0
RELEASE_HEIGHT_CM = 67.0
RELEASE_DISTANCE_CM = 60.0
RELEASE_WIDTH_PX = 3840

_DISPLAY_DIRS_ENV = "FOVEXP_DISPLAYS"


#: The narrowest pixel a display profile may describe, width / height (and its inverse).
MIN_PIXEL_ASPECT = 0.5


class Display(BaseModel):
    """A display profile: what the viewing geometry and colour stages need to know."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    width_px: int = Field(gt=0, le=32768)
    height_px: int = Field(gt=0, le=32768)
    width_cm: float = Field(gt=0, le=1000)
    height_cm: float = Field(gt=0, le=1000)
    distance_cm: float = Field(gt=0, le=1000)
    refresh_hz: float = Field(gt=0, le=1000)
    peak_luminance_cd_m2: float = Field(gt=0, le=100000)
    gamma: float = Field(gt=0.5, le=5.0)

    @model_validator(mode="after")
    def _square_pixels(self) -> Display:
        # The geometry takes one pitch per axis; a profile whose pixels are far from square is
        # a typo in its size or resolution (the paper's LG OLED55CX: 1.000), not a display.
        aspect = (self.width_cm / self.width_px) / (self.height_cm / self.height_px)
        if not MIN_PIXEL_ASPECT <= aspect <= 1.0 / MIN_PIXEL_ASPECT:
            raise ValueError(
                f"its pixels would be {aspect:.3g} times as wide as tall ({self.width_cm:g} x "
                f"{self.height_cm:g} cm at {self.width_px} x {self.height_px} px); a display's "
                f"are square to within a factor {1 / MIN_PIXEL_ASPECT:g}: check the size and "
                "the resolution"
            )
        return self

    @property
    def horizontal_field_deg(self) -> float:
        """Full horizontal field of view, ``2 atan(w / 2D)`` (docs/METHOD.md, 4: 80.8 deg)."""
        return math.degrees(2.0 * math.atan(0.5 * self.width_cm / self.distance_cm))


#: The release's display (docs/METHOD.md, 5), for the ``release`` preset.
RELEASE_DISPLAY = Display(
    name="release-prototype",
    width_px=RELEASE_WIDTH_PX,
    height_px=2160,
    width_cm=RELEASE_WIDTH_CM,
    height_cm=RELEASE_HEIGHT_CM,
    distance_cm=RELEASE_DISTANCE_CM,
    refresh_hz=60.0,
    peak_luminance_cd_m2=100.0,
    gamma=2.2,
)


def display_search_path() -> list[Path]:
    """Folders searched for ``NAME.yaml`` display profiles, in order: ``$FOVEXP_DISPLAYS``
    (colon-separated), ``./protocols/displays``, the shipped profiles."""
    dirs = [Path(p) for p in os.environ.get(_DISPLAY_DIRS_ENV, "").split(":") if p]
    out: list[Path] = []
    for d in [*dirs, Path.cwd() / "protocols" / "displays", shipped_displays()]:
        if d.resolve() not in {o.resolve() for o in out}:  # run from the repo: listed once
            out.append(d)
    return out


def load_display(name_or_path: str | Path) -> Display:
    """Load a display profile by name (searched in :func:`display_search_path`) or by path.

    Raises :class:`FovexpError` naming the file and the field for a missing or bad profile.

    >>> from fovexp import load_display
    >>> lg = load_display("lg-oled55cx")  # the paper's display (section 5.1)
    >>> lg.width_px, lg.height_px, lg.distance_cm, round(lg.horizontal_field_deg, 1)
    (3840, 2160, 71.5, 80.8)
    """
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        for d in display_search_path():
            if (d / f"{name_or_path}.yaml").is_file():
                path = d / f"{name_or_path}.yaml"
                break
        else:
            raise FovexpError(
                f"display profile {str(name_or_path)!r} not found "
                f"(looked in {', '.join(str(d) for d in display_search_path())})"
            )
    data = read_yaml(path, "display profile")
    if not isinstance(data, dict):
        raise FovexpError(f"display profile {path} must be a mapping of fields")
    try:
        return Display(**data)
    except ValidationError as exc:
        raise validation_error(f"display profile {path}", exc) from None


# Cephes' atan (Moshier, cephes/double/atan.c): a rational function after reduction to
# |x| <= 0.66, relative error about 2e-16 (the same float32 eccentricities as libm's atan2 on
# every pixel of 4K frames, measured). Inline arithmetic, where libm's atan2 is a call per
# pixel: the per-pixel loops of the sigma map vectorise (measured 4x faster, issue 29).
_ATAN_P = (-8.750608600031904122785e-1, -1.615753718733365076637e1,
           -7.500855792314704667340e1, -1.228866684490136173410e2,
           -6.485021904942025371773e1)
_ATAN_Q = (2.485846490142306297962e1, 1.650270098316988542046e2, 4.328810604912902668951e2,
           4.853903996359136964868e2, 1.945506571482613964425e2)
_TAN_3PI_8 = 2.41421356237309504880
_MOREBITS = 6.123233995736765886130e-17  # pi/2 = 1.5707963267948966 + this


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH, error_model="numpy")
def _atan2_upper(y, x):  # pragma: no cover - compiled
    """atan2(y, x) for y >= 0 (the upper half plane, [0, pi]): Cephes' atan of y / |x|,
    mirrored for x < 0. Branch-free (selects), so that a loop over it vectorises."""
    t = y / abs(x)  # +inf at x = 0: atan gives pi/2
    big = t > _TAN_3PI_8
    mid = t > 0.66
    # one division for the three reductions (-1 / t, (t - 1) / (t + 1), t / 1 = t exactly):
    # the same quotients, and division is what the loop waits for
    r = (-1.0 if big else (t - 1.0 if mid else t)) / (t if big else (t + 1.0 if mid else 1.0))
    base = 0.5 * math.pi if big else (0.25 * math.pi if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    p0, p1, p2, p3, p4 = _ATAN_P
    q0, q1, q2, q3, q4 = _ATAN_Q
    z = r * r
    poly = z * ((((p0 * z + p1) * z + p2) * z + p3) * z + p4) / (
        ((((z + q0) * z + q1) * z + q2) * z + q3) * z + q4)
    a = base + ((r * poly + r) + extra)
    return a if x > 0.0 else math.pi - a


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH, error_model="numpy")
def _angle_deg(ux, uy, vx, vy, d):  # pragma: no cover - compiled
    """Angle (deg) between the rays from the eye to screen points u and v (cm from the
    screen centre, eye at distance d on the normal): atan2(|u x v|, u . v)."""
    dot = ux * vx + uy * vy + d * d
    cx = uy * d - d * vy
    cy = d * vx - ux * d
    cz = ux * vy - uy * vx
    return math.degrees(_atan2_upper(math.sqrt(cx * cx + cy * cy + cz * cz), dot))


#: The float32 maps' arctangent (:func:`_atan2_upper32`): atan(r) = r + r z P(z), z = r^2,
#: |r| <= tan(pi / 8), P a degree-4 fit (Chebyshev nodes) of (atan(r) / r - 1) / z, relative
#: error 5e-8 in P, 3e-9 in atan: a tenth of a float32 step.
_ATAN32_P = tuple(np.float32(c) for c in (
    -0.3333333180635729, 0.19999548430326353, -0.14264175034669263, 0.10745672962716125,
    -0.06457294167601789))
_TAN_PI_8_F32 = np.float32(0.41421356237309504880)
_TAN_3PI_8_F32 = np.float32(_TAN_3PI_8)
_ZERO_F32 = np.float32(0.0)
_PI_F32 = np.float32(math.pi)
_HALF_PI_F32 = np.float32(0.5 * math.pi)
_QUARTER_PI_F32 = np.float32(0.25 * math.pi)
_DEG_PER_RAD_F32 = np.float32(180.0 / math.pi)


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH, error_model="numpy")
def _atan2_upper32(y, x):  # pragma: no cover - compiled
    """:func:`_atan2_upper` in float32 (``y``, ``x`` float32, y >= 0): the same reduction
    with one division (y / |x|, (y - |x|) / (y + |x|) or -|x| / y, picked from y and |x|) and
    a polynomial (:data:`_ATAN32_P`). Float32's divider does four values where float64's
    does one (or two) in the same time: the map's division and square root are its cost."""
    ax = abs(x)
    big = y > _TAN_3PI_8_F32 * ax
    mid = y > _TAN_PI_8_F32 * ax
    r = (-ax if big else (y - ax if mid else y)) / (y if big else (y + ax if mid else ax))
    base = _HALF_PI_F32 if big else (_QUARTER_PI_F32 if mid else _ZERO_F32)
    p0, p1, p2, p3, p4 = _ATAN32_P
    z = r * r
    # (a Numba intrinsic: mypy counts its typing context as an argument)
    p: float = fma(fma(fma(fma(p4, z, p3), z, p2), z, p1), z, p0)  # type: ignore[call-arg]
    a = base + fma(r * z, p, r)
    return a if x > _ZERO_F32 else _PI_F32 - a


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH, error_model="numpy")
def _angle_deg32(ux, uy, vx, vy, d):  # pragma: no cover - compiled
    """:func:`_angle_deg` as the float32 maps take it: |u x v|^2 and u . v in float64, each
    rounded once to float32, then the square root, the arctangent and the degrees in
    float32 (:func:`_atan2_upper32`): within 5 float32 steps of the float64 angle (about
    1e-5 deg at 40 deg; tests/enhancer/test_geometry.py), in half its time."""
    dot = ux * vx + uy * vy + d * d
    cx = uy * d - d * vy
    cy = d * vx - ux * d
    cz = ux * vy - uy * vx
    s = math.sqrt(np.float32(cx * cx + cy * cy + cz * cz))
    return _atan2_upper32(s, np.float32(dot)) * _DEG_PER_RAD_F32


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH, error_model="numpy")
def _ppd_at(ux, uy, d, pitch):  # pragma: no cover - compiled
    """(pi / 180) L / pitch with L the eye-to-point distance (see ViewingGeometry.ppd)."""
    return (math.pi / 180.0) * math.sqrt(ux * ux + uy * uy + d * d) / pitch


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _angle_points(ux, uy, vx, vy, d, out):  # pragma: no cover - compiled
    """:func:`_angle_deg` of 1-D arrays of points (a loop, not a ufunc: see
    :func:`fovexp.jit.flat_broadcast`)."""
    for i in range(out.shape[0]):
        out[i] = _angle_deg(ux[i], uy[i], vx, vy, d)


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _ppd_points(ux, uy, d, pitch, out):  # pragma: no cover - compiled
    """:func:`_ppd_at` of 1-D arrays of points."""
    for i in range(out.shape[0]):
        out[i] = _ppd_at(ux[i], uy[i], d, pitch)


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _exact_grids(ux, uy, vx, vy, d, pitch, single, ecc, ppd):  # pragma: no cover - compiled
    """Eccentricity and ppd of every pixel, written into ``ecc`` and ``ppd`` (float32 or
    float64: the ppd's float64 values rounded once; ``single``: the eccentricity's last
    steps in float32, :func:`_angle_deg32`); rows in parallel."""
    for y in numba.prange(uy.shape[0]):
        if single:
            for x in range(ux.shape[0]):
                ecc[y, x] = _angle_deg32(ux[x], uy[y], vx, vy, d)
        else:
            for x in range(ux.shape[0]):
                ecc[y, x] = _angle_deg(ux[x], uy[y], vx, vy, d)
        for x in range(ux.shape[0]):
            ppd[y, x] = _ppd_at(ux[x], uy[y], d, pitch)


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _ppd_grid(ux, uy, d, pitch, ppd):  # pragma: no cover - compiled
    """px/deg of every pixel into ``ppd`` (the float64 values rounded once); rows in
    parallel."""
    for y in numba.prange(uy.shape[0]):
        row = ppd[y]
        for x in range(ux.shape[0]):
            row[x] = _ppd_at(ux[x], uy[y], d, pitch)


@dataclass(frozen=True)
class ViewingGeometry:
    """The geometry of an image on a display.

    The image covers pixels ``[x0, x0 + width) x [y0, y0 + height)`` of a full-screen frame of
    ``screen_width x screen_height`` pixels (by default the image *is* the frame: a screen
    size left at 0 is the image's, the origin 0). Pixel
    coordinates are the image's own; the pitch is the frame's. Attributes are in the units
    their names say; ``pitch_*_cm`` is the size of one frame pixel on the screen.

    >>> import numpy as np
    >>> from fovexp import ViewingGeometry, load_display
    >>> g = ViewingGeometry.for_image(load_display("lg-oled55cx"), 3840, 2160)
    >>> gaze = g.gaze_px((0.5, 0.5))  # normalised screen coordinates -> px
    >>> gaze
    (1919.5, 1079.5)
    >>> g.ppd(np.array([gaze[0]]), np.array([gaze[1]])).round(1)  # px/deg on the axis
    array([39.3])
    >>> g.eccentricity_deg(np.array([2312.5, 3839.0]), np.array([1079.5, 2159.0]), gaze).round(2)
    array([ 9.89, 44.33])
    """

    width_px: int
    height_px: int
    pitch_x_cm: float
    pitch_y_cm: float
    distance_cm: float
    model: GeometryModel = "exact"
    #: constant pixels per degree of the ``linear`` and ``release`` models
    ppd_constant: float = float("nan")
    screen_width_px: int = 0
    screen_height_px: int = 0
    x0_px: int = 0
    y0_px: int = 0

    def __post_init__(self) -> None:
        # a screen size left at 0: the image is the whole frame (as for_image makes it)
        if self.screen_width_px == 0:
            object.__setattr__(self, "screen_width_px", self.width_px)
        if self.screen_height_px == 0:
            object.__setattr__(self, "screen_height_px", self.height_px)

    @classmethod
    def for_image(
        cls, display: Display, width_px: int, height_px: int, model: GeometryModel = "exact",
        viewport: tuple[int, int, int, int] | None = None,
    ) -> ViewingGeometry:
        """Geometry of a ``width_px x height_px`` image shown full screen on ``display``, or,
        with ``viewport = (x0, y0, screen_width, screen_height)``, shown at ``(x0, y0)`` of a
        full-screen frame of that size (e.g. the right half of a split-screen stimulus)."""
        sw, sh, x0, y0 = width_px, height_px, 0, 0
        if viewport is not None:
            x0, y0, sw, sh = (int(v) for v in viewport)
            if x0 < 0 or y0 < 0 or x0 + width_px > sw or y0 + height_px > sh:
                raise FovexpError(
                    f"viewport {viewport}: a {width_px}x{height_px} image does not fit at "
                    f"({x0}, {y0}) of a {sw}x{sh} frame"
                )
        if model == "release":
            # The release's own screen and constant ppd, scaled to the frame width.
            return cls(
                width_px, height_px, RELEASE_WIDTH_CM / sw, RELEASE_HEIGHT_CM / sh,
                RELEASE_DISTANCE_CM, "release", RELEASE_PPD_AT_3840 * sw / RELEASE_WIDTH_PX,
                sw, sh, x0, y0,
            )
        return cls(
            width_px, height_px, display.width_cm / sw, display.height_cm / sh,
            display.distance_cm, model, sw / display.horizontal_field_deg, sw, sh, x0, y0,
        )

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height_px, self.width_px)

    def gaze_px(self, gaze_norm: tuple[float, float]) -> tuple[float, float]:
        """Normalised gaze ``(x_h, x_v)`` in [0, 1] to pixel coordinates (x right, y down)."""
        gx, gy = (float(v) for v in gaze_norm)
        if not (math.isfinite(gx) and math.isfinite(gy) and 0.0 <= gx <= 1.0 and 0.0 <= gy <= 1.0):
            raise FovexpError(
                f"gaze ({gx}, {gy}) is outside the screen: normalised coordinates must be in [0, 1]"
            )
        return (gx * self.screen_width_px - 0.5 - self.x0_px,
                gy * self.screen_height_px - 0.5 - self.y0_px)

    def _screen_cm(
        self, x_px: np.ndarray | np.float64, y_px: np.ndarray | np.float64
    ) -> tuple[np.ndarray | np.float64, np.ndarray | np.float64]:
        """Image pixel coordinates to cm from the screen centre."""
        return ((x_px + self.x0_px + 0.5) - 0.5 * self.screen_width_px) * self.pitch_x_cm, (
            (y_px + self.y0_px + 0.5) - 0.5 * self.screen_height_px
        ) * self.pitch_y_cm

    def eccentricity_deg(
        self, x_px: np.ndarray, y_px: np.ndarray, gaze_px: tuple[float, float]
    ) -> np.ndarray:
        """Retinal eccentricity (deg) of pixels ``(x_px, y_px)`` for a gaze at ``gaze_px``.

        ``exact``: the angle between the two rays from the eye, ``atan2(|u x v|, u . v)``.
        ``linear``: on-screen distance in px over the constant px/deg (paper section 5.1).
        ``release``: ``atan(R / D)`` with ``R`` the on-screen distance in cm (docs/METHOD.md, 5).
        """
        x_px = np.asarray(x_px, dtype=np.float64)
        y_px = np.asarray(y_px, dtype=np.float64)
        gx, gy = gaze_px
        if self.model == "linear":
            return np.hypot(x_px - gx, y_px - gy) / self.ppd_constant
        if self.model == "release":
            r_cm = np.hypot((x_px - gx) * self.pitch_x_cm, (y_px - gy) * self.pitch_y_cm)
            return np.degrees(np.arctan(r_cm / self.distance_cm))
        shape, (x_flat, y_flat) = flat_broadcast(x_px, y_px)
        ux, uy = self._screen_cm(x_flat, y_flat)
        vx, vy = self._screen_cm(np.float64(gx), np.float64(gy))
        out = np.empty(x_flat.shape)
        _angle_points(ux, uy, vx, vy, float(self.distance_cm), out)
        return out.reshape(shape)

    def ppd(self, x_px: np.ndarray, y_px: np.ndarray) -> np.ndarray:
        """Local pixels per degree at pixels ``(x_px, y_px)``.

        ``exact``: a pixel at distance ``L = D / cos(theta)`` from the eye (theta off the
        screen normal) subtends ``pitch / L`` rad across the line of sight, so
        ``ppd = (pi / 180) L / pitch``: 39.3 px/deg on axis on the LG profile, 51 at its
        horizontal edge (a 10.9 arcmin blur there is about 9 px, docs/METHOD.md, 4). Along the
        radius the screen is foreshortened by a further cos(theta); an isotropic screen-space
        blur cannot follow that, so the across-the-line-of-sight figure is used.
        ``linear`` and ``release``: the model's constant.
        """
        x_px = np.asarray(x_px, dtype=np.float64)
        y_px = np.asarray(y_px, dtype=np.float64)
        if self.model != "exact":
            return np.full(np.broadcast(x_px, y_px).shape, self.ppd_constant)
        shape, (x_flat, y_flat) = flat_broadcast(x_px, y_px)
        ux, uy = self._screen_cm(x_flat, y_flat)
        out = np.empty(x_flat.shape)
        _ppd_points(ux, uy, float(self.distance_cm), math.sqrt(self.pitch_x_cm * self.pitch_y_cm),
                    out)
        return out.reshape(shape)

    def eccentricity_and_ppd_maps(
        self, gaze_px: tuple[float, float], dtype: type = np.float32,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel eccentricity (deg) and pixels per degree, (H, W) maps of ``dtype``: the
        same formulas as :meth:`eccentricity_deg` and :meth:`ppd`, evaluated on the pixel
        grid in float64 and rounded once to ``dtype``; but for the ``exact`` model's float32
        eccentricity, whose square root, arctangent and degrees are float32 arithmetic
        (:func:`_angle_deg32`: within 5 float32 steps, about 1e-5 deg, of the float64
        angle)."""
        if self.model != "exact":
            x, y = self.grid()
            e: np.ndarray = self.eccentricity_deg(x, y, gaze_px).astype(dtype, copy=False)
            return e, np.full(e.shape, self.ppd_constant, dtype=dtype)
        ecc: np.ndarray = np.empty(self.shape, dtype=dtype)
        ppd: np.ndarray = np.empty(self.shape, dtype=dtype)
        _exact_grids(*self.exact_terms(gaze_px), np.dtype(dtype) == np.float32, ecc, ppd)
        return ecc, ppd

    def ppd_map(self, dtype: type = np.float32) -> np.ndarray:
        """Pixels per degree of every pixel, an (H, W) map of ``dtype``: :meth:`ppd` on the
        pixel grid (the ``exact`` model's in float64, rounded once; the same values as
        :meth:`eccentricity_and_ppd_maps`'). It does not depend on the gaze: the enhancer
        keeps it across frames."""
        if self.model != "exact":
            return np.full(self.shape, self.ppd_constant, dtype=dtype)
        ux, uy, _, _, d, pitch = self.exact_terms((0.0, 0.0))
        out: np.ndarray = np.empty(self.shape, dtype=dtype)
        _ppd_grid(ux, uy, d, pitch, out)
        return out

    def exact_terms(
        self, gaze_px: tuple[float, float],
    ) -> tuple[np.ndarray, np.ndarray, float, float, float, float]:
        """What the ``exact`` model's compiled per-pixel formulas (:func:`_angle_deg`,
        :func:`_ppd_at`) take: the screen position (cm from its centre) of every pixel column
        and row, the gaze's, the viewing distance (cm) and the pitch (cm, the geometric mean
        of the two)."""
        x, y = self.grid()
        ux, uy = self._screen_cm(x[0], y[:, 0])
        vx, vy = self._screen_cm(np.float64(gaze_px[0]), np.float64(gaze_px[1]))
        return (np.asarray(ux), np.asarray(uy), float(vx), float(vy), float(self.distance_cm),
                math.sqrt(self.pitch_x_cm * self.pitch_y_cm))

    def max_eccentricity_and_ppd(self, gaze_px: tuple[float, float]) -> tuple[float, float]:
        """The largest eccentricity (deg) and px/deg over the image, float64: both are at
        its corners. On a flat screen the points within an angle of the line of sight form
        an ellipse (a plane cut through a cone), a convex set, so the angle is largest at a
        corner of the rectangle; ppd grows with the eye-to-point distance, a convex function
        (the ``linear`` and ``release`` models: a distance on the screen, convex too)."""
        x = np.array([0.0, self.width_px - 1.0, 0.0, self.width_px - 1.0])
        y = np.array([0.0, 0.0, self.height_px - 1.0, self.height_px - 1.0])
        return (float(self.eccentricity_deg(x, y, gaze_px).max()),
                float(np.max(self.ppd(x, y))))

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Broadcastable pixel-centre coordinates ``(x[None, :], y[:, None])``."""
        return (
            np.arange(self.width_px, dtype=np.float64)[None, :],
            np.arange(self.height_px, dtype=np.float64)[:, None],
        )


def cpd_to_cpp(f_cpd: np.ndarray | float, ppd: np.ndarray | float) -> np.ndarray:
    """Cycles per degree to cycles per pixel at ``ppd`` pixels per degree."""
    return np.asarray(f_cpd) / ppd


def cpp_to_cpd(f_cpp: np.ndarray | float, ppd: np.ndarray | float) -> np.ndarray:
    """Cycles per pixel to cycles per degree at ``ppd`` pixels per degree."""
    return np.asarray(f_cpp) * ppd

