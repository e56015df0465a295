"""Generate the small synthetic scenes that make a dry run work on a fresh clone.

Deterministic (fixed seeds, numpy + Pillow only): running it again rewrites byte-identical PNGs
and prints the manifest entries with their sha256. The scenes stand in for the paper's rendered
frames (section 6.1 "Stimuli": dark and bright scenes with high-contrast, high-frequency detail):
each mixes flat regions (sky, walls, panels) with textures (bricks, foliage, fabric, stone, text).
They are 960x540 and palette-quantised so that all ten stay a few hundred KB.

    python stimuli/generate.py            # writes stimuli/generated/*.png, updates manifest.yaml
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, ImageDraw

HERE = Path(__file__).resolve().parent
OUT = HERE / "generated"
W, H = 960, 540
COLOURS = 48  # palette size: keeps the PNGs small (flat regions stay flat, textures stay sharp)


def _gradient(top: tuple[float, float, float], bottom: tuple[float, float, float]) -> np.ndarray:
    t = np.linspace(0.0, 1.0, H)[:, None, None]
    return (1 - t) * np.asarray(top) + t * np.asarray(bottom) * np.ones((H, W, 3))


def _bricks(rng: np.random.Generator, h: int, w: int, bw: int, bh: int, base) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    row = y // bh
    xs = x + (row % 2) * (bw // 2)
    col = xs // bw
    mortar = ((y % bh) < 2) | ((xs % bw) < 2)
    shade = rng.uniform(0.75, 1.15, size=(row.max() + 2, col.max() + 2))[row, col]
    grain = 0.06 * np.sin(0.9 * x + 0.3 * y) * np.sin(1.3 * y)
    img = np.asarray(base)[None, None, :] * (shade + grain)[..., None]
    img[mortar] = np.asarray(base) * 0.35
    return img


def _fabric(h: int, w: int, period: float, base, angle: float) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(float)
    u = x * np.cos(angle) + y * np.sin(angle)
    v = -x * np.sin(angle) + y * np.cos(angle)
    weave = 0.5 + 0.25 * np.sin(2 * np.pi * u / period) + 0.25 * np.sin(2 * np.pi * v / period)
    return np.asarray(base)[None, None, :] * (0.6 + 0.6 * weave)[..., None]


def _stone(rng: np.random.Generator, h: int, w: int, cells: int, base) -> np.ndarray:
    pts = rng.uniform(0, 1, size=(cells, 2)) * (w, h)
    y, x = np.mgrid[0:h, 0:w].astype(float)
    d = np.full((h, w), np.inf)
    d2 = np.full((h, w), np.inf)
    idx = np.zeros((h, w), int)
    for i, (px, py) in enumerate(pts):
        di = np.hypot(x - px, y - py)
        closer = di < d
        d2 = np.where(closer, d, np.minimum(d2, di))
        idx = np.where(closer, i, idx)
        d = np.minimum(d, di)
    shade = rng.uniform(0.6, 1.2, size=cells)[idx]
    edge = np.clip((d2 - d) / 3.0, 0, 1)
    return np.asarray(base)[None, None, :] * (shade * (0.3 + 0.7 * edge))[..., None]


def _draw_foliage(draw: ImageDraw.ImageDraw, rng: np.random.Generator, box, n: int, hue) -> None:
    x0, y0, x1, y1 = box
    for _ in range(n):
        cx, cy = rng.uniform(x0, x1), rng.uniform(y0, y1)
        r = rng.uniform(2, 7)
        k = rng.uniform(0.4, 1.2)
        c = tuple(int(np.clip(255 * k * v, 0, 255)) for v in hue)
        draw.ellipse((cx - r, cy - r * 0.6, cx + r, cy + r * 0.6), fill=c)


def _draw_text(draw: ImageDraw.ImageDraw, rng: np.random.Generator, box, colour) -> None:
    # Stroke "glyphs" rather than a font: no font file dependency, still fine high-contrast detail.
    x0, y0, x1, y1 = box
    y = y0
    while y < y1 - 10:
        x = x0
        while x < x1 - 8:
            for _ in range(rng.integers(1, 4)):
                a, b = rng.uniform(0, 6, 2), rng.uniform(0, 9, 2)
                draw.line((x + a[0], y + b[0], x + a[1], y + b[1]), fill=colour, width=1)
            x += 8 if rng.uniform() > 0.15 else 16
        y += 14


def scene(index: int) -> np.ndarray:
    """Scene ``index`` (0..14) as uint8 RGB; its look is fixed by ``index`` alone."""
    rng = np.random.default_rng(1000 + index)
    dark = index % 3 == 2  # some dark scenes, as in the paper's selection
    k = 0.35 if dark else 1.0
    sky = _gradient((0.35 * k, 0.55 * k, 0.85 * k), (0.75 * k, 0.85 * k, 0.95 * k))
    img = sky.copy()
    horizon = int(H * rng.uniform(0.35, 0.55))
    kind = index % 5
    if kind == 0:
        img[horizon:] = _bricks(rng, H - horizon, W, 48, 20, (0.65 * k, 0.33 * k, 0.22 * k))
    elif kind == 1:
        img[horizon:] = _stone(rng, H - horizon, W, 140, (0.6 * k, 0.58 * k, 0.52 * k))
    elif kind == 2:
        img[horizon:] = _fabric(H - horizon, W, 5.0, (0.5 * k, 0.2 * k, 0.45 * k), 0.5)
    elif kind == 3:
        img[horizon:] = _bricks(rng, H - horizon, W, 30, 14, (0.55 * k, 0.55 * k, 0.6 * k))
    else:
        img[horizon:] = _fabric(H - horizon, W, 3.5, (0.3 * k, 0.45 * k, 0.25 * k), 1.1)
    # A flat panel (a wall or a sign) and a striped object on each side of the centre, so both
    # the left half and its mirror carry detail at several eccentricities.
    pil = Image.fromarray((np.clip(img, 0, 1) * 255).astype(np.uint8))
    draw = ImageDraw.Draw(pil)
    for side in (0, 1):
        px = int(rng.uniform(60, 300)) + side * 480
        pw, ph = int(rng.uniform(90, 150)), int(rng.uniform(80, 160))
        py = horizon - ph + int(rng.uniform(-20, 40))
        flat = tuple(int(v) for v in rng.uniform(40, 220, 3) * k)
        draw.rectangle((px, py, px + pw, py + ph), fill=flat)
        if rng.uniform() < 0.6:
            _draw_text(draw, rng, (px + 8, py + 8, px + pw - 8, py + ph // 2), (20, 20, 20))
        cx = int(rng.uniform(20, 440)) + side * 480
        _draw_foliage(draw, rng, (cx - 70, horizon - 130, cx + 70, horizon + 10), 900,
                      (0.25 * k, 0.6 * k, 0.2 * k))
        for j in range(12):
            x = px + pw + 20 + 3 * j
            grey = (230, 230, 230) if j % 2 else (15, 15, 15)
            draw.line((x, horizon - 60, x, horizon + 40), fill=grey)
    return np.asarray(pil)


def main() -> None:
    OUT.mkdir(exist_ok=True)
    entries = []
    for i in range(15):
        name = f"scene-{i:02d}"
        path = OUT / f"{name}.png"
        rgb = Image.fromarray(scene(i))
        # Median-cut palette without dithering: deterministic and compact.
        pal = rgb.quantize(colors=COLOURS, method=Image.Quantize.MEDIANCUT,
                           dither=Image.Dither.NONE)
        pal.save(path, optimize=True)
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        entries.append({
            "id": name,
            "path": f"generated/{name}.png",
            "source": "stimuli/generate.py (synthetic, deterministic)",
            "licence": "CC0-1.0",
            "sha256": digest,
        })
        print(f"{name}: {path.stat().st_size / 1024:.0f} KB {digest}")
    manifest = HERE / "manifest.yaml"
    header = (
        "# Stimuli the protocols name by id. Paths are relative to this file; sha256 is checked\n"
        "# at load. See README.md for adding the paper's frames or a lab's renders.\n"
    )
    old = yaml.safe_load(manifest.read_text()) if manifest.exists() else None
    keep = [e for e in (old or {}).get("images", []) if not e["id"].startswith("scene-")]
    manifest.write_text(header + yaml.safe_dump({"images": entries + keep}, sort_keys=False))


if __name__ == "__main__":
    main()
