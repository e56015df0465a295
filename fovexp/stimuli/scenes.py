"""The fifteen generated scenes: synthetic stand-ins for the paper's rendered frames, drawn at
any resolution, byte for byte the same on every machine.

Paper section 5.1 ("Stimuli") chose 4K frames "such that they include both dark and bright
scenes with high-contrast and high-spatial-frequency details"; section 6.1 chose the validation
scenes for "diversity in illumination, contrast and spatial frequencies". Each scene here is a
street: a sky (flat, or a night sky with single-pixel stars), 1 px wires, buildings with flat
walls and sharp-edged windows or 1 px siding, a ground plane in perspective (bricks,
cobblestones, planks, a woven carpet or grass) whose texture runs from a few pixels per element
at the bottom to the pixel limit at the horizon, trees of leaves a few pixels wide, a fence
whose pickets repeat every 2 to 8 px, and a sign of real text (Pillow's bitmap font, 1 px
strokes at its native size). Dark scenes are lit by windows, lamps and stars.

The layout scales with the frame (a sign covers the same fraction of the screen at every
resolution); the fine structure does not: grain, mortar, wires, stars, pickets and the smallest
text are 1 to 3 *pixels* at every resolution, as in a frame rendered at that resolution. So a
scene generated at 3840x2160 has content up to the display's Nyquist frequency (24 cpd at the
screen centre on the paper's LG OLED55CX), not an upscaled small picture.

Determinism: only integer arithmetic, IEEE float64 ``+ - * /`` and ``floor`` (exactly rounded
on every machine; no sin/exp/pow, no reductions, no BLAS), integer hashes instead of a random
generator whose stream could change between numpy versions, the layout drawn from a splitmix64
stream in Python integers, and text from Pillow's bitmap font (pasted bitmaps, no FreeType
rasterisation). :func:`png_bytes` writes the PNG with a fixed filter and Python's zlib at a
fixed level; the pinned pixel hash (:func:`pixels_sha256`) tells a different deflate
implementation from different pixels.

The sha256 of each scene's PNG and of its pixels are pinned per resolution in the shipped
``scenes.yaml`` (``fovexp.stimuli.folder``, which writes and checks the files).
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: the scenes' ids, in protocol order (calibration: 0-4, validation: 5-14)
N_SCENES = 15
#: deflate level of the written PNGs (part of the pinned bytes: do not change without re-pinning)
PNG_LEVEL = 3
#: the reference frame the layout is designed at (the paper's display)
DESIGN_SIZE = (3840, 2160)

GROUNDS = ("bricks", "cobbles", "planks", "weave", "grass")


@dataclass(frozen=True)
class SceneSpec:
    """What a scene is made of; everything else follows from ``seed``."""

    index: int
    ground: str
    dark: bool
    seed: int

    @property
    def id(self) -> str:
        return scene_id(self.index)

    def describe(self) -> str:
        light = "night, lit windows, lamps and stars" if self.dark else "daylight"
        return (f"{light}; {self.ground} ground in perspective, buildings, trees, fence, "
                "sign with text, wires")


def scene_id(index: int) -> str:
    return f"scene-{index:02d}"


#: five ground textures in turn; dark scenes 1, 4 (calibration) and 7, 10, 13 (validation)
SCENES: tuple[SceneSpec, ...] = tuple(
    SceneSpec(i, GROUNDS[i % 5], i % 3 == 1, 7919 * (i + 1)) for i in range(N_SCENES))
SCENE_IDS: tuple[str, ...] = tuple(s.id for s in SCENES)


def spec_of(image_id: str) -> SceneSpec | None:
    """The scene named ``image_id`` (``scene-07``), or None when it is not a generated one."""
    return SCENES[SCENE_IDS.index(image_id)] if image_id in SCENE_IDS else None


# -- deterministic randomness -------------------------------------------------------------------
_M64 = (1 << 64) - 1


class _Stream:
    """splitmix64 in Python integers: the layout's random numbers, the same everywhere."""

    def __init__(self, seed: int) -> None:
        self.state = seed & _M64

    def next(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & _M64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _M64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _M64
        return z ^ (z >> 31)

    def uniform(self, lo: float, hi: float) -> float:
        return lo + (hi - lo) * ((self.next() >> 11) / float(1 << 53))

    def integer(self, lo: int, hi: int) -> int:
        """Uniform in [lo, hi]."""
        return lo + self.next() % (hi - lo + 1)

    def chance(self, p: float) -> bool:
        return self.uniform(0.0, 1.0) < p


_U = np.uint32


def _mix(x: np.ndarray) -> np.ndarray:
    """Chris Wellons' lowbias32 integer hash (uint32 in, uint32 out, wrapping arithmetic)."""
    x = x ^ (x >> _U(16))
    x = x * _U(0x7FEB352D)
    x = x ^ (x >> _U(15))
    x = x * _U(0x846CA68B)
    return x ^ (x >> _U(16))


def _u32(a: np.ndarray | int) -> np.ndarray:
    # at least 1-d: numpy warns of wrapping in scalar arithmetic, never in array arithmetic
    return np.atleast_1d(np.asarray(a, dtype=np.int64) & 0xFFFFFFFF).astype(np.uint32)


def hash2(seed: int, a: np.ndarray | int, b: np.ndarray | int) -> np.ndarray:
    """A uint32 hash of two integer coordinates (broadcast) under ``seed``."""
    return _mix(_mix(_u32(a) ^ _u32(seed)) ^ (_u32(b) * _U(0x9E3779B9)))


def _unit(h: np.ndarray, n: int) -> np.ndarray:
    """A hash as an integer in [0, n)."""
    return (h % _U(n)).astype(np.int64)


# -- the canvas -----------------------------------------------------------------------------------
RGB = tuple[int, int, int]


class _Canvas:
    """An RGB uint8 frame and the frame-relative units the layout is given in."""

    def __init__(self, width: int, height: int) -> None:
        self.w, self.h = width, height
        self.img = np.zeros((height, width, 3), np.uint8)
        #: pixels that give light (lit windows, stars, backlit signs): kept when a night
        #: scene's other pixels are dimmed
        self.glow = np.zeros((height, width), bool)
        #: layout scale: 1 at the design size, 1/8 at 480x270
        self.u = min(width / DESIGN_SIZE[0], height / DESIGN_SIZE[1])

    def px(self, design_px: float, least: int = 1) -> int:
        """A length given at the design size, at this resolution (at least ``least`` px)."""
        return max(least, int(design_px * self.u + 0.5))

    def box(self, x0: int, y0: int, x1: int, y1: int) -> tuple[int, int, int, int] | None:
        """The box clipped to the frame (None when nothing is left)."""
        x0, y0 = max(0, x0), max(0, y0)
        x1, y1 = min(self.w, x1), min(self.h, y1)
        return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None

    def fill(self, x0: int, y0: int, x1: int, y1: int, colour: RGB, glow: bool = False) -> None:
        b = self.box(x0, y0, x1, y1)
        if b is not None:
            self.img[b[1]:b[3], b[0]:b[2]] = colour
            self.glow[b[1]:b[3], b[0]:b[2]] = glow

    def paint(self, x0: int, y0: int, mask: np.ndarray, colour: RGB | np.ndarray,
              glow: bool = False) -> None:
        """Set the pixels of ``mask`` (placed with its corner at x0, y0) to ``colour`` (one
        colour, or an array of the mask's shape + (3,))."""
        h, w = mask.shape
        b = self.box(x0, y0, x0 + w, y0 + h)
        if b is None:
            return
        m = mask[b[1] - y0:b[3] - y0, b[0] - x0:b[2] - x0]
        view = self.img[b[1]:b[3], b[0]:b[2]]
        if isinstance(colour, np.ndarray):
            c = colour[b[1] - y0:b[3] - y0, b[0] - x0:b[2] - x0]
            view[m] = c[m]
        else:
            view[m] = colour
        self.glow[b[1]:b[3], b[0]:b[2]][m] = glow


def _shade(colour: RGB | np.ndarray, level: np.ndarray) -> np.ndarray:
    """``colour`` times ``level`` / 256 (level: int array, any shape) as uint8 RGB."""
    c = np.asarray(colour, np.int64)
    out = (np.asarray(level, np.int64)[..., None] * c) >> 8
    return np.clip(out, 0, 255).astype(np.uint8)


def _grain(seed: int, ys: np.ndarray, xs: np.ndarray, amp: int) -> np.ndarray:
    """Per-pixel noise in [-amp, amp] (int64), fixed to absolute pixel coordinates."""
    return _unit(hash2(seed, xs, ys), 2 * amp + 1) - amp


def _lerp(a: RGB, b: RGB, num: int, den: int) -> RGB:
    return tuple(int(a[k] + (b[k] - a[k]) * num // den) for k in range(3))  # type: ignore[return-value]


# -- text ----------------------------------------------------------------------------------------
EYE_CHART = ("E", "F P", "T O Z", "L P E D", "P E C F D", "E D F C Z P", "F E L O P Z D",
             "D E F P O T E C", "L E F O D P C T")
PROSE = (
    "The quick brown fox jumps over the lazy dog. Pack my box with five dozen liquor jugs.",
    "Sphinx of black quartz, judge my vow. How vexingly quick daft zebras jump!",
    "Peripheral vision detects but cannot resolve a band of spatial frequencies;",
    "foveated rendering drops them, and noise tuned to that band puts them back.",
    "0123456789 ABCDEFGHIJKLMNOPQRSTUVWXYZ abcdefghijklmnopqrstuvwxyz (){}[]<>/?!",
    "Opening hours: Mon-Fri 08:30-18:00, Sat 09:00-13:00. Platform 4, car 12, seat 38.",
)


@lru_cache(maxsize=1)
def _font():  # noqa: ANN202
    from PIL import ImageFont

    # Pillow's built-in bitmap font: its glyphs are pasted as they are (no FreeType
    # rasterisation, whose output depends on the FreeType version).
    return ImageFont.load_default_imagefont()


@lru_cache(maxsize=512)
def _text_mask(text: str, scale: int) -> np.ndarray:
    """``text`` in the bitmap font (6 px per character, 11 px per line at scale 1), each font
    pixel drawn as a ``scale`` x ``scale`` block (nearest neighbour: the edges stay sharp)."""
    from PIL import Image, ImageDraw

    font = _font()
    x0, y0, x1, y1 = font.getbbox(text)
    im = Image.new("L", (max(1, x1), 11))
    ImageDraw.Draw(im).text((0, 0), text, font=font, fill=255)
    m = np.asarray(im) > 0
    if scale > 1:
        m = np.repeat(np.repeat(m, scale, axis=0), scale, axis=1)
    return m


# -- the scene's parts, far to near ---------------------------------------------------------------
def _sky(c: _Canvas, s: _Stream, seed: int, horizon: int, dark: bool) -> None:
    top: RGB = (8, 12, 34) if dark else (70, 120, 200)
    low: RGB = (30, 34, 60) if dark else (200, 220, 240)
    top = _lerp(top, (s.integer(0, 60),) * 3, s.integer(0, 3), 10)  # type: ignore[arg-type]
    rows = np.arange(horizon, dtype=np.int64)[:, None]
    den = max(1, horizon - 1)
    sky = np.asarray(top, np.int64) + (np.asarray(low, np.int64) - top) * rows // den
    c.img[:horizon] = sky[:, None, :].astype(np.uint8)
    c.glow[:horizon] = dark  # a night sky is drawn in its own (dark) colours
    if dark:  # stars: single pixels, a few a bright
        ys, xs = np.mgrid[0:horizon, 0:c.w]
        h = hash2(seed + 11, xs, ys)
        star = h < _U(int(0.0012 * 2**32))
        level = 90 + _unit(h >> _U(8), 166)
        c.img[:horizon][star] = np.clip(level[star, None] * np.array([1, 1, 1]) + [0, 0, 10],
                                        0, 255).astype(np.uint8)
        # a moon: a flat disc with a sharp rim
        mx, my, r = int(c.w * s.uniform(0.55, 0.9)), int(horizon * s.uniform(0.2, 0.5)), c.px(60)
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        c.paint(mx - r, my - r, xx * xx + yy * yy <= r * r, (235, 232, 210), glow=True)
    else:  # flat clouds with sharp lower edges (cumulus-like stacks of ellipses)
        for _ in range(s.integer(3, 6)):
            cx, cy = int(c.w * s.uniform(0.0, 1.0)), int(horizon * s.uniform(0.15, 0.6))
            grey = s.integer(225, 250)
            for _k in range(5):
                rx, ry = c.px(s.uniform(120, 320)), c.px(s.uniform(40, 90))
                ox, oy = int(rx * s.uniform(-1.2, 1.2)), int(ry * s.uniform(-0.8, 0.2))
                yy, xx = np.mgrid[-ry:ry + 1, -rx:rx + 1]
                ell = xx * xx * ry * ry + yy * yy * rx * rx <= rx * rx * ry * ry
                c.paint(cx + ox - rx, cy + oy - ry, ell & (yy <= ry // 2), (grey,) * 3)


def _wires(c: _Canvas, s: _Stream, horizon: int, dark: bool) -> None:
    """1 px cables sagging between poles: single-pixel lines on a flat sky."""
    colour: RGB = (70, 70, 80) if dark else (25, 25, 30)
    for _ in range(s.integer(2, 4)):
        x0, x1 = 0, c.w
        y0 = int(horizon * s.uniform(0.1, 0.7))
        y1 = int(horizon * s.uniform(0.1, 0.7))
        sag = c.px(s.uniform(20, 120))
        xs = np.arange(x0, x1, dtype=np.int64)
        ys = y0 + (y1 - y0) * (xs - x0) // (x1 - x0) + 4 * sag * (xs - x0) * (x1 - xs) // (
            (x1 - x0) ** 2)
        ok = (ys >= 0) & (ys < horizon)
        c.img[ys[ok], xs[ok]] = colour
        # thickness 1 px, but connect steep parts so the line is unbroken
        step = np.abs(np.diff(ys))
        for k in np.nonzero(step > 1)[0][:2000]:
            lo, hi = sorted((int(ys[k]), int(ys[k + 1])))
            c.img[max(lo, 0):max(min(hi, horizon), 0), xs[k]] = colour


def _buildings(c: _Canvas, s: _Stream, seed: int, horizon: int, dark: bool) -> None:
    """A row of buildings on the horizon: flat walls, sharp window frames, 1 px siding; at
    night some windows are lit."""
    x = -int(c.w * s.uniform(0.0, 0.05))
    n = 0
    while x < c.w:
        n += 1
        bw = int(c.w * s.uniform(0.07, 0.17))
        bh = int(horizon * s.uniform(0.25, 0.75))
        top = horizon - bh
        wall: RGB = (s.integer(90, 210), s.integer(80, 180), s.integer(70, 160))
        c.fill(x, top, x + bw, horizon, wall)
        # a roof edge (2 px, darker) and a cornice line
        c.fill(x, top, x + bw, top + c.px(6, 2), _lerp(wall, (20, 20, 20), 6, 10))
        if s.chance(0.4):  # siding: a dark 1 px line every few px (the finest structure)
            period = s.integer(3, 6)
            ys = np.arange(top + c.px(12), horizon)
            lines = ys[(ys % period) == 0]
            b = c.box(x, 0, x + bw, 1)
            if b is not None:
                c.img[lines, b[0]:b[2]] = _lerp(wall, (0, 0, 0), 3, 10)
        ww, wh = c.px(s.uniform(40, 90), 2), c.px(s.uniform(60, 130), 3)
        gx, gy = ww + c.px(s.uniform(25, 60), 2), wh + c.px(s.uniform(30, 70), 2)
        frame = c.px(4, 1)
        glass_day: RGB = (s.integer(40, 90), s.integer(60, 110), s.integer(80, 140))
        for wy in range(top + c.px(40, 2), horizon - wh - c.px(20, 1), gy):
            for wx in range(x + c.px(30, 1), x + bw - ww - c.px(10, 1), gx):
                c.fill(wx - frame, wy - frame, wx + ww + frame, wy + wh + frame,
                       _lerp(wall, (255, 255, 255), 5, 10))
                lit = dark and int(hash2(seed + 3, wx, wy)[0]) % 10 < 4
                glass = (255, 214, 140) if lit else ((18, 20, 28) if dark else glass_day)
                c.fill(wx, wy, wx + ww, wy + wh, glass, glow=lit)
                # mullions: 1 px crosses
                c.fill(wx + ww // 2, wy, wx + ww // 2 + 1, wy + wh, (30, 30, 30), glow=lit)
                c.fill(wx, wy + wh // 3, wx + ww, wy + wh // 3 + 1, (30, 30, 30), glow=lit)
        x += bw + (c.px(s.uniform(0, 60), 0) if s.chance(0.5) else 0)
        if n > 60:
            break


def _ground_coords(c: _Canvas, horizon: int, tilt: float, r0: int,
                   r1: int) -> tuple[np.ndarray, ...]:
    """Texture coordinates of a ground plane seen in perspective (float64, world units =
    pixels at the bottom row) on rows ``r0`` to ``r1``, and the size in px of one world unit on
    each of these rows."""
    rows = np.arange(r0, r1, dtype=np.float64)
    dy = rows - (horizon - 1.0)  # 1 at the horizon row
    bottom = float(c.h - horizon)
    per_px = bottom / dy[:, None]  # world units per px across
    xs = np.arange(c.w, dtype=np.float64)[None, :] - c.w / 2.0
    tx = xs * per_px
    tz = (bottom * bottom / tilt) / dy[:, None] + 0.0 * xs
    px_per_unit = dy / bottom  # px per world unit, per row
    return tx, tz, px_per_unit


def _fade(px_per_unit: np.ndarray, feature_units: float) -> np.ndarray:
    """Contrast kept of a feature ``feature_units`` wide on each row (a crude mip level:
    texture finer than ~1 px fades to its mean instead of aliasing), in 1/256 steps."""
    size_px = px_per_unit * feature_units
    return np.clip(np.floor((size_px - 0.75) * 128.0), 0, 256).astype(np.int64)[:, None]


#: rows of the ground drawn at once (bounds the memory of a 4K scene; the pixels do not
#: depend on it)
GROUND_STRIP_ROWS = 128


def _ground(c: _Canvas, s: _Stream, seed: int, horizon: int, kind: str) -> None:
    """The ground plane, in strips of rows (every pixel depends on its own coordinates only)."""
    tilt = s.uniform(0.35, 0.6)
    colours: list[RGB] = []
    if kind == "bricks":
        colours.append((s.integer(140, 180), s.integer(60, 90), s.integer(40, 60)))
    elif kind == "planks":
        colours.append((s.integer(150, 190), s.integer(100, 130), s.integer(55, 80)))
    elif kind == "cobbles":
        colours.append((s.integer(120, 160), s.integer(115, 150), s.integer(105, 140)))
    elif kind == "weave":
        colours.append((s.integer(120, 200), s.integer(30, 80), s.integer(40, 90)))
        colours.append((s.integer(200, 240), s.integer(170, 210), s.integer(120, 170)))
    else:
        colours.append((s.integer(50, 80), s.integer(110, 150), s.integer(30, 50)))
    for r0 in range(horizon, c.h, GROUND_STRIP_ROWS):
        r1 = min(c.h, r0 + GROUND_STRIP_ROWS)
        c.img[r0:r1] = _ground_rows(c, seed, horizon, kind, tilt, colours, r0, r1)
    c.glow[horizon:] = False


def _ground_rows(c: _Canvas, seed: int, horizon: int, kind: str, tilt: float,
                 colours: list[RGB], r0: int, r1: int) -> np.ndarray:
    u = c.u
    tx, tz, ppu = _ground_coords(c, horizon, tilt, r0, r1)
    ys = np.arange(r0, r1, dtype=np.int64)[:, None]
    xs = np.arange(c.w, dtype=np.int64)[None, :]
    grain = _grain(seed + 5, ys, xs, 10)  # pixel-level grain on every surface

    def size(design: float) -> float:
        """A texture size in world units (px at the bottom row) at this resolution."""
        return max(1.0, design * u)

    if kind == "bricks":
        bw, bh, mortar = size(64.0), size(24.0), size(3.0)
        row = np.floor(tz / bh).astype(np.int64)
        shifted = tx + (row & 1) * (bw / 2.0)
        col = np.floor(shifted / bw).astype(np.int64)
        fx = shifted - col * bw
        fz = tz - row * bh
        base = colours[0]
        level = 176 + _unit(hash2(seed + 7, col, row), 96)  # per brick
        sp = size(2.0)
        speck = _unit(hash2(seed + 8, np.floor(tx / sp).astype(np.int64),
                            np.floor(tz / sp).astype(np.int64)), 60) - 30
        level = level + (speck * _fade(ppu, sp) >> 8)
        is_mortar = (fx < mortar) | (fz < mortar)
        fade = _fade(ppu, mortar)
        level = np.where(is_mortar, level - ((level - 70) * fade >> 8), level)
        colour = _shade(base, level + grain)
    elif kind == "cobbles":
        cell, grout = size(40.0), size(3.0)
        ix, iz = np.floor(tx / cell).astype(np.int64), np.floor(tz / cell).astype(np.int64)
        d1 = np.full(tx.shape, np.inf)
        d2 = np.full(tx.shape, np.inf)
        site = np.zeros(tx.shape, np.int64)
        for oz in (-1, 0, 1):
            for ox in (-1, 0, 1):
                cx, cz = ix + ox, iz + oz
                h = hash2(seed + 9, cx, cz)
                sx = (cx + (h & _U(0xFFFF)) / 65536.0) * cell
                sz = (cz + (h >> _U(16)) / 65536.0) * cell
                d = (tx - sx) * (tx - sx) + (tz - sz) * (tz - sz)
                closer = d < d1
                d2 = np.where(closer, d1, np.minimum(d2, d))
                site = np.where(closer, _u32(cx * 7919 + cz).astype(np.int64), site)
                d1 = np.minimum(d1, d)
        base = colours[0]
        level = 150 + _unit(hash2(seed + 10, site, 1), 110)
        # joints where the two nearest stones are nearly equidistant (d2 - d1 = 2 * distance
        # to the bisector * the stones' spacing): dark grout of ~3 world units
        joint = (d2 - d1) < 2.0 * grout * cell
        fade = _fade(ppu, grout)
        level = np.where(joint, level - ((level - 40) * fade >> 8), level)
        colour = _shade(base, level + grain)
    elif kind == "planks":
        pw, bl, wl, seam_w = size(36.0), size(400.0), size(90.0), size(2.0)
        plank = np.floor(tz / pw).astype(np.int64)
        offs = _unit(hash2(seed + 12, plank, 0), 4096).astype(np.float64)
        offs = offs * (bl / 4096.0)
        board = np.floor((tx + offs) / bl).astype(np.int64)
        # wood grain: thin lines along the boards, wobbling slowly (piecewise-linear noise)
        lat = np.floor(tx / wl)
        t = tx / wl - lat
        a = _unit(hash2(seed + 13, lat.astype(np.int64), plank), 9).astype(np.float64)
        b = _unit(hash2(seed + 13, lat.astype(np.int64) + 1, plank), 9).astype(np.float64)
        wob = a + (b - a) * t
        line = np.floor((tz - plank * pw) * (1.5 / size(1.0)) + wob).astype(np.int64)
        streak = _unit(hash2(seed + 14, line, board), 70) - 35
        base = colours[0]
        level = 170 + _unit(hash2(seed + 15, board, plank), 70) + (
            streak * _fade(ppu, 0.7) >> 8)
        seam = ((tz - plank * pw) < seam_w) | (((tx + offs) - board * bl) < seam_w)
        level = np.where(seam, level - ((level - 50) * _fade(ppu, seam_w) >> 8), level)
        colour = _shade(base, level + grain)
    elif kind == "weave":
        t = size(3.0)  # thread width
        ix, iz = np.floor(tx / t).astype(np.int64), np.floor(tz / t).astype(np.int64)
        warp = ((ix + iz) & 3) < 2  # a 2/2 twill
        c1, c2 = colours
        thread = np.where(warp, ix, iz + 1_000_003)
        level = 200 + _unit(hash2(seed + 16, thread, 5), 56)
        fade = _fade(ppu, t)
        mean = (np.asarray(c1, np.int64) + np.asarray(c2, np.int64)) // 2
        mix = np.where(warp[..., None], np.asarray(c1, np.int64), np.asarray(c2, np.int64))
        mixed = mean + ((mix - mean) * fade[..., None] >> 8)
        colour = _shade(mixed, level + grain)
    else:  # grass: blades as short vertical streaks, one family per column, finer far away
        blade = size(14.0)
        seg = np.floor(tz / blade).astype(np.int64)
        lean = np.floor(tz * (0.15 / size(1.0))).astype(np.int64)
        colx = xs + lean
        h = hash2(seed + 17, colx, seg)
        base = colours[0]
        level = 120 + _unit(h, 150)
        level = 195 + ((level - 195) * _fade(ppu, blade * 0.5) >> 8)
        colour = _shade(base, level + grain)
    return colour


def _tree(c: _Canvas, s: _Stream, seed: int, x: int, ground_y: int, size: float) -> None:
    """A trunk with bark stripes and a canopy of leaves ~10 px wide at the design size, each
    leaf with a dark rim: edges everywhere inside the canopy."""
    th = int(c.px(size * 380))
    tw = c.px(size * 40, 2)
    trunk_top = ground_y - th
    b = c.box(x - tw // 2, trunk_top, x + tw // 2 + 1, ground_y)
    if b is not None:
        xs = np.arange(b[0], b[2])
        stripe = 70 + _unit(hash2(seed + 20, xs, 0), 60)
        c.img[b[1]:b[3], b[0]:b[2]] = _shade((150, 110, 80), stripe)[None, :, :]
    rx, ry = c.px(size * 260, 3), c.px(size * 200, 3)
    cy = trunk_top - ry // 2
    box = c.box(x - rx, cy - ry, x + rx + 1, cy + ry + 1)
    if box is None:
        return
    x0, y0, x1, y1 = box
    ys = np.arange(y0, y1, dtype=np.int64)[:, None]
    xs = np.arange(x0, x1, dtype=np.int64)[None, :]
    cell = c.px(12, 3)
    ix, iy = xs // cell, ys // cell
    d1 = np.full((y1 - y0, x1 - x0), 1 << 40, np.int64)
    d2 = d1.copy()
    best_x = np.zeros_like(d1)
    best_y = np.zeros_like(d1)
    for oy in (-1, 0, 1):
        for ox in (-1, 0, 1):
            cx, cyy = ix + ox, iy + oy
            h = hash2(seed + 21, cx, cyy)
            sx = cx * cell + _unit(h, cell)
            sy = cyy * cell + _unit(h >> _U(8), cell)
            d = (xs - sx) ** 2 + (ys - sy) ** 2
            closer = d < d1
            d2 = np.where(closer, d1, np.minimum(d2, d))
            best_x = np.where(closer, sx, best_x)
            best_y = np.where(closer, sy, best_y)
            d1 = np.minimum(d1, d)
    sx, sy = best_x, best_y
    # a leaf belongs to the canopy when its centre is inside the ellipse: a leafy silhouette
    inside = (sx - x) ** 2 * ry * ry + (sy - cy) ** 2 * rx * rx <= (rx * ry) ** 2
    h = hash2(seed + 22, sx, sy)
    green: RGB = (s.integer(40, 80), s.integer(100, 150), s.integer(30, 60))
    level = 110 + _unit(h, 150) - ((sy - (cy - ry)) * 60 // max(1, 2 * ry))
    rim = (d2 - d1) <= 2 * cell  # the leaf's edge: ~1 px
    level = np.where(rim, level // 3, level)
    c.paint(x0, y0, inside, _shade(green, level))
    # (the trunk was filled directly: it never glows)
    if b is not None:
        c.glow[b[1]:b[3], b[0]:b[2]] = False


def _fence(c: _Canvas, s: _Stream, x_off: int, y_base: int) -> None:
    """A fence across part of the frame whose pickets repeat every 8, 6, 4, 3 and 2 px: a
    resolution chart in the scene (its finest part at the display's Nyquist limit)."""
    height = c.px(s.uniform(120, 200), 4)
    x_start = x_off + int(c.w * s.uniform(0.02, 0.12))
    width = int(c.w * s.uniform(0.35, 0.45))
    colour: RGB = (235, 235, 230)
    top = y_base - height
    segments = (8, 6, 4, 3, 2)
    seg_w = width // len(segments)
    for k, period in enumerate(segments):
        x0 = x_start + k * seg_w
        b = c.box(x0, top, x0 + seg_w, y_base)
        if b is None:
            continue
        xs = np.arange(b[0], b[2])
        picket = (xs - x0) % period < (period + 1) // 2
        view = c.img[b[1]:b[3], b[0]:b[2]]
        view[:, picket] = colour
        c.glow[b[1]:b[3], b[0]:b[2]][:, picket] = False
    rail = c.px(10, 1)
    for ry in (top + height // 5, top + 4 * height // 5):
        c.fill(x_start, ry, x_start + width, ry + rail, _lerp(colour, (0, 0, 0), 3, 10))


def _sign(c: _Canvas, s: _Stream, x: int, y_base: int, dark: bool) -> None:
    """A sign on two posts: a flat panel with an eye chart (scales 6 to 1) and lines of prose
    at the bitmap font's native size (1 px strokes)."""
    pw, ph = int(c.w * s.uniform(0.16, 0.22)), int(c.h * s.uniform(0.22, 0.3))
    post = c.px(14, 2)
    top = y_base - ph - c.px(160, 2)
    light = s.chance(0.7)
    panel: RGB = (240, 238, 226) if light else (24, 60, 40)
    ink: RGB = (15, 15, 20) if light else (240, 240, 230)
    backlit = dark and s.chance(0.5)  # at night, a lit sign or a dark one
    for px_ in (x + pw // 6, x + 5 * pw // 6):
        c.fill(px_ - post // 2, top + ph, px_ + post // 2 + 1, y_base, (60, 60, 66))
    border = c.px(6, 1)
    c.fill(x - border, top - border, x + pw + border, top + ph + border, (40, 40, 44))
    c.fill(x, top, x + pw, top + ph, panel, glow=backlit)
    margin = c.px(24, 1)
    ty = top + margin
    bottom = top + ph - margin
    scales = [max(1, int(v * c.u + 0.5)) for v in (6, 5, 4, 3, 3, 2, 2, 1, 1)]
    for text, sc in zip(EYE_CHART, scales, strict=True):
        m = _text_mask(text, sc)
        if ty + m.shape[0] > bottom:
            return
        m = m[:, : max(0, pw - 2 * margin)]
        c.paint(x + (pw - m.shape[1]) // 2, ty, m, ink, glow=backlit)
        ty += m.shape[0] + max(1, 3 * sc)
    k = 0
    while ty + 11 <= bottom:
        m = _text_mask(PROSE[k % len(PROSE)], 1)[:, : max(0, pw - 2 * margin)]
        c.paint(x + margin, ty, m, ink, glow=backlit)
        ty += 13
        k += 1


def _lamp_post(c: _Canvas, x: int, y_base: int, size: float) -> tuple[int, int, float]:
    """A street lamp's post; returns where its light is (:func:`_lamp_light`)."""
    h = c.px(size * 520, 4)
    c.fill(x - c.px(6, 1), y_base - h, x + c.px(6, 1) + 1, y_base, (150, 150, 160))
    return x, y_base - h, size


def _lamp_light(c: _Canvas, x: int, cy: int, size: float) -> None:
    """A lamp's bright head and its halo, falling off as R^2 / (R^2 + d^2), added to what is
    around it (drawn after a night scene is dimmed)."""
    r = c.px(size * 140, 3)
    b = c.box(x - r, cy - r, x + r + 1, cy + r + 1)
    if b is None:
        return
    yy = np.arange(b[1], b[3], dtype=np.int64)[:, None] - cy
    xx = np.arange(b[0], b[2], dtype=np.int64)[None, :] - x
    d2 = xx * xx + yy * yy
    core = c.px(size * 14, 1) ** 2
    glow = 170 * core // (core + d2)
    view = c.img[b[1]:b[3], b[0]:b[2]].astype(np.int64)
    view = view + (glow[..., None] * np.array([255, 220, 160]) >> 8)
    view[d2 <= core] = (255, 250, 235)
    c.img[b[1]:b[3], b[0]:b[2]] = np.clip(view, 0, 255).astype(np.uint8)


def render_scene(index: int, width: int, height: int) -> np.ndarray:
    """Scene ``index`` (0..14) at ``width`` x ``height`` as uint8 RGB (H, W, 3)."""
    if not 0 <= index < N_SCENES:
        raise ValueError(f"no scene {index} (0..{N_SCENES - 1})")
    if width < 16 or height < 16:
        raise ValueError(f"scene size {width}x{height} is too small (16x16 at least)")
    spec = SCENES[index]
    c = _Canvas(width, height)
    s = _Stream(spec.seed)
    horizon = int(height * s.uniform(0.42, 0.55))
    _sky(c, s, spec.seed, horizon, spec.dark)
    _wires(c, s, horizon, spec.dark)
    _buildings(c, s, spec.seed, horizon, spec.dark)
    _ground(c, s, spec.seed, horizon, spec.ground)
    # the left half (the reference, mirrored on the right) gets a sign, a fence and trees at
    # several eccentricities; the right half its own
    lamps = []
    for side in (0, 1):
        off = side * (width // 2)
        _tree(c, s, spec.seed + side, off + int(width * s.uniform(0.05, 0.45)),
              horizon + int((height - horizon) * s.uniform(0.05, 0.2)), s.uniform(0.7, 1.2))
        if side == 0 or s.chance(0.5):
            _fence(c, s, off, horizon + int((height - horizon) * s.uniform(0.15, 0.35)))
        _tree(c, s, spec.seed + 10 + side, off + int(width * s.uniform(0.02, 0.48)),
              horizon + int((height - horizon) * s.uniform(0.3, 0.6)), s.uniform(1.0, 1.6))
        lamp = (off + int(width * s.uniform(0.05, 0.45)),
                horizon + int((height - horizon) * s.uniform(0.1, 0.3)), s.uniform(0.8, 1.2))
        if spec.dark:
            lamps.append(_lamp_post(c, *lamp))
        _sign(c, s, off + int(width * s.uniform(0.04, 0.25)),
              horizon + int((height - horizon) * s.uniform(0.45, 0.75)), spec.dark)
    if spec.dark:  # night: what does not give light is dimmed, then the lamps are lit
        dim = (c.img.astype(np.uint16) * 64 >> 8).astype(np.uint8)
        c.img = np.where(c.glow[..., None], c.img, dim)
        for x, y, size in lamps:
            _lamp_light(c, x, y, size)
    return c.img


# -- test material for the paper's analyses of outputs (section 6.2 and 6.4) ----------------------
def render_pan(index: int, width: int, height: int, frames: int, step_px: int) -> np.ndarray:
    """A camera pan across scene ``index`` (section 6.2's test sequence): frame k is the
    ``width`` x ``height`` window at x = k ``step_px`` of the scene drawn (frames - 1)
    ``step_px`` wider, so the content moves ``step_px`` to the left per frame. uint8 RGB
    (frames, H, W, 3); deterministic as :func:`render_scene`."""
    if frames < 2 or step_px < 0:
        raise ValueError(f"a pan needs 2 or more frames and a step >= 0 px (got {frames}, "
                         f"{step_px})")
    wide = render_scene(index, width + (frames - 1) * step_px, height)
    return np.stack([wide[:, k * step_px:k * step_px + width] for k in range(frames)])


def render_stereo_pair(index: int, width: int, height: int, far_px: int = 4,
                       near_px: int = 16) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A stereo pair of two planes with a known disparity (section 6.4's test material):
    scene ``index`` as a background plane at disparity ``far_px`` and a rectangle of scene
    ``index + 7`` (mod 15) as a nearer plane at ``near_px``, in the right third of the frame.

    Disparity d = x_left - x_right in pixels, on the left image's grid (a left pixel at x is
    seen at x - d by the right eye; parallel cameras, so d >= 0 and nearer is larger). The
    right eye sees a strip of ``near_px - far_px`` px of background beside the rectangle's right
    edge that the left eye does not (a disocclusion). Returns ``(left, right, disparity)``:
    uint8 RGB (H, W, 3) twice and float32 (H, W)."""
    if not 0 <= far_px < near_px:
        raise ValueError(f"need 0 <= far < near (got far {far_px}, near {near_px} px)")
    background = render_scene(index, width + far_px, height)
    left = background[:, :width].copy()
    right = background[:, far_px:far_px + width].copy()
    disparity = np.full((height, width), float(far_px), np.float32)
    x0, y0 = (width * 3) // 5, (height * 3) // 10
    fw, fh = max(16, width // 4), max(16, (height * 2) // 5)
    fw = min(fw, width - x0)
    plane = render_scene((index + 7) % N_SCENES, fw, fh)
    left[y0:y0 + fh, x0:x0 + fw] = plane
    xr0 = x0 - near_px  # the plane as the right eye sees it
    lo, hi = max(0, xr0), min(width, xr0 + fw)
    right[y0:y0 + fh, lo:hi] = plane[:, lo - xr0:hi - xr0]
    disparity[y0:y0 + fh, x0:x0 + fw] = near_px
    return left, right, disparity


# -- PNG and hashes ------------------------------------------------------------------------------
def pixels_sha256(pixels: np.ndarray) -> str:
    """sha256 of an image's samples (shape, type and bytes): what a PNG decodes to, whatever
    deflate implementation wrote it."""
    a = np.ascontiguousarray(pixels)
    h = hashlib.sha256(f"{a.shape}:{a.dtype.str}:".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def png_bytes(pixels: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """A lossless PNG of uint8 or uint16 grey or RGB samples, the same bytes for the same
    pixels wherever zlib's deflate is the reference one: pypng (no scanline filter: on these
    scenes' pixel grain it compresses better than any of PNG's predictors) with Python's zlib
    at a fixed ``level``. Pillow's encoder chooses filters adaptively and carries its own zlib
    build, so its bytes vary between versions."""
    import png

    a = np.ascontiguousarray(pixels)
    if a.dtype not in (np.uint8, np.uint16) or a.ndim not in (2, 3) or (
            a.ndim == 3 and a.shape[2] != 3):
        raise ValueError(f"png_bytes: need uint8/uint16 grey or RGB, got {a.dtype} {a.shape}")
    h, w = a.shape[:2]
    writer = png.Writer(w, h, greyscale=a.ndim == 2, bitdepth=8 * a.itemsize,
                        compression=level)
    buf = io.BytesIO()
    writer.write(buf, a.reshape(h, -1))
    return buf.getvalue()
