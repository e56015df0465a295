"""Stimuli: the generated scenes, a lab's own frames, the folder they are kept in, and the checks
that a session shows exactly the pixels it was meant to (paper section 5.1, "Stimuli").

Protocols name images by id. Two kinds of id:

* **generated scenes** ``scene-00`` ... ``scene-14`` (:mod:`.scenes`): fovexp ships their
  definitions (the generator) and, in ``scenes.yaml`` of the package ``fovexp.stimuli.shipped``, the
  sha256 of their PNG file and of their pixels for each pinned resolution (:data:`PINNED`);
  ``fovexp stimuli generate`` writes them into ``generated/WxH/`` of the stimulus folder;
* **a lab's frames** (``fovexp stimuli add``): ``frames/ID.png`` listed in the stimulus folder's
  own ``manifest.yaml`` with source, licence and sha256.

The **stimulus folder** is the lab's (the package's files are read-only data). It is, first
found: ``--stimuli DIR``; the protocol's ``stimuli:`` key (a folder or its ``manifest.yaml``,
relative to the protocol file); ``stimuli/`` of the study folder (``fovexp init``) the current
folder is in; ``$FOVEXP_STIMULI``; ``./stimuli`` of the current folder (in
the project's clone, the top-level ``stimuli/``); the per-user data folder
(``platformdirs.user_data_dir("fovexp")/stimuli``, e.g. ``~/.local/share/fovexp/stimuli``).

A session shows every image at its frame size: a real session at the display's own resolution
(``3840x2160`` on the paper's LG OLED55CX) and refuses any other size; a dry run in a smaller
window takes the nearest generated resolution and scales it to the window, and says so
(:meth:`StimulusSet.check`); a dry run at the display's own size scales nothing
(:func:`may_scale`): it is a rehearsal of the real session.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fovexp import FovexpError, did_you_mean, read_yaml, validation_error, write_bytes_atomic
from fovexp import read_samples as fovexp_read_samples

from . import scenes

#: environment variable naming the stimulus folder
ENV_VAR = "FOVEXP_STIMULI"
#: a stimulus folder's own manifest (the lab's frames)
MANIFEST = "manifest.yaml"
#: what marks a study folder (``fovexp init``): its ``stimuli/`` is the stimulus folder of every
#: command run in it
STUDY_FILE = "fovexp-study.yaml"
#: the shipped pins of the generated scenes (in the package ``fovexp.stimuli.shipped``)
SCENE_PINS = "scenes.yaml"
#: where generated scenes and added frames go in a stimulus folder
GENERATED, FRAMES = "generated", "frames"
#: a dry run's window (``fovexp run --dry-run``; ``--window`` changes it)
DRY_RUN_SIZE = (480, 270)
#: resolutions whose sha256 ship with fovexp: the paper's display, and the dry run's window
PINNED: tuple[tuple[int, int], ...] = ((3840, 2160), DRY_RUN_SIZE)

Size = tuple[int, int]
_SHA = r"^[0-9a-f]{64}$"
_ID = r"^[A-Za-z0-9_.-]{1,64}$"
_WXH = r"^[0-9]{1,5}x[0-9]{1,5}$"


def size_text(size: Size) -> str:
    return f"{size[0]}x{size[1]}"


def may_scale(dry_run: bool, frame_size: Size, native_size: Size) -> bool:
    """Whether a session showing frames of ``frame_size`` on a display of ``native_size`` may
    scale its images: only a dry run in a window of another size (480x270 by default). A dry
    run at the display's own size is a rehearsal of the real session, and refuses what the real
    session refuses (size, id, sha256), with the same line."""
    return bool(dry_run) and tuple(frame_size) != tuple(native_size)


def parse_size(text: str) -> Size:
    """``"3840x2160"`` -> (3840, 2160); raises FovexpError."""
    m = re.fullmatch(r"\s*(\d{1,5})\s*[xX]\s*(\d{1,5})\s*", text)
    if m is None or not (16 <= int(m[1]) and 16 <= int(m[2])):
        raise FovexpError(f"{text!r} is not a size WIDTHxHEIGHT (16x16 at least)")
    return int(m[1]), int(m[2])


# -- the manifests -------------------------------------------------------------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Pin(_Strict):
    """sha256 of a generated scene's PNG file and of its pixels (:func:`scenes.pixels_sha256`):
    a machine whose zlib deflates differently writes other bytes for the same pixels."""

    file: str = Field(pattern=_SHA)
    pixels: str = Field(pattern=_SHA)


class SceneEntry(_Strict):
    """A generated scene in the shipped ``scenes.yaml``."""

    id: str = Field(pattern=_ID)
    description: str
    source: str
    licence: str
    sha256: dict[str, Pin]  # by resolution "WxH"


class ScenePins(_Strict):
    scenes: list[SceneEntry]


class StimulusEntry(_Strict):
    """A lab's frame in its stimulus folder's ``manifest.yaml``."""

    id: str = Field(pattern=_ID)
    path: str  # relative to the manifest, or absolute
    source: str
    licence: str
    sha256: str = Field(pattern=_SHA)


class LabManifest(_Strict):
    """A stimulus folder's ``manifest.yaml``: the lab's frames, and the sha256 of scenes it
    generated at resolutions fovexp does not pin (another display's)."""

    images: list[StimulusEntry] = Field(default_factory=list)
    generated: dict[str, dict[str, Pin]] = Field(default_factory=dict)


MANIFEST_HEADER = (
    "# A fovexp stimulus folder: the lab's own frames (fovexp stimuli add) and the sha256 of\n"
    "# scenes generated here at resolutions fovexp does not pin. Paths are relative to this\n"
    "# file. Every file is checked against its sha256 before a session opens its window.\n"
)


def _shipped_pins_path() -> Path:
    from fovexp import shipped_stimuli

    return shipped_stimuli() / SCENE_PINS


def load_scene_pins(path: Path | None = None) -> dict[str, SceneEntry]:
    """The shipped generated-scene entries by id."""
    path = path or _shipped_pins_path()
    try:
        pins = ScenePins.model_validate(read_yaml(path, "scene pins"))
    except ValidationError as exc:
        raise validation_error(f"scene pins {path}", exc) from None
    return {e.id: e for e in pins.scenes}


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


_hash_cache: dict[tuple[str, int, int], str] = {}


def _cached_sha256(path: Path) -> str:
    """sha256 of a file, remembered by (path, mtime, size) within this process: the runner
    checks at load and again when the session is created."""
    st = path.stat()
    key = (str(path), st.st_mtime_ns, st.st_size)
    if key not in _hash_cache:
        _hash_cache[key] = sha256_file(path)
    return _hash_cache[key]


# -- reading image files as they are -------------------------------------------------------------
def read_samples(path: Path) -> np.ndarray:
    """A stimulus file's samples as stored (:func:`fovexp.read_samples`): uint8 or uint16,
    (H, W) grey or (H, W, 3) RGB. An alpha channel is dropped when every pixel is opaque and
    refused otherwise (a stimulus is shown opaque); float samples are refused (export 8- or
    16-bit)."""
    a = fovexp_read_samples(path)
    if a.dtype not in (np.uint8, np.uint16):
        raise FovexpError(f"{path}: {a.dtype} samples; export it with 8- or 16-bit integers")
    if a.ndim == 3 and a.shape[2] in (2, 4):
        if a[..., -1].min() < np.iinfo(a.dtype).max:
            raise FovexpError(f"{path}: has transparent pixels; flatten it onto its background "
                              "first (a stimulus is shown opaque)")
        a = a[..., 0] if a.shape[2] == 2 else a[..., :3]
    return a


def image_size(path: Path) -> Size:
    """(width, height) from the file's header."""
    from PIL import Image

    try:
        with Image.open(path) as im:
            return int(im.size[0]), int(im.size[1])
    except Exception as exc:
        raise FovexpError(f"{path}: cannot be read as an image ({type(exc).__name__})") from None


# -- the stimulus folder --------------------------------------------------------------------------
def user_stimulus_folder() -> Path:
    """The per-user default: ``platformdirs.user_data_dir("fovexp")/stimuli``."""
    import platformdirs

    return Path(platformdirs.user_data_dir("fovexp", appauthor=False)) / "stimuli"


def find_study(start: Path) -> Path | None:
    """The study folder (``fovexp init``: a folder holding :data:`STUDY_FILE`) that ``start``
    is in, or None."""
    here = Path(start).resolve()
    for folder in (here, *here.parents):
        if (folder / STUDY_FILE).is_file():
            return folder
    return None


def find_folder(explicit: str | Path | None = None, protocol_key: str | None = None,
                protocol_dir: Path | None = None) -> tuple[Path, Path, str]:
    """The stimulus folder, its manifest file and how it was found (module docstring)."""
    if explicit is not None:
        return _folder_and_manifest(Path(explicit).expanduser(), "--stimuli")
    if protocol_key is not None:
        p = Path(protocol_key).expanduser()
        if not p.is_absolute() and protocol_dir is not None:
            p = protocol_dir / p
        return _folder_and_manifest(p.resolve(), "the protocol's stimuli key")
    study = find_study(Path.cwd())
    if study is not None:  # a study's own folder, also from its subfolders
        return study / "stimuli", study / "stimuli" / MANIFEST, f"the study folder {study}"
    env = os.environ.get(ENV_VAR)
    if env:
        return _folder_and_manifest(Path(env).expanduser(), f"${ENV_VAR}")
    here = Path.cwd() / "stimuli"
    if here.is_dir():
        return here.resolve(), here.resolve() / MANIFEST, "./stimuli"
    user = user_stimulus_folder()
    return user, user / MANIFEST, "the user data folder"


def _folder_and_manifest(p: Path, how: str) -> tuple[Path, Path, str]:
    p = p.resolve()
    if p.suffix in (".yaml", ".yml"):
        return p.parent, p, how
    return p, p / MANIFEST, how


# -- checking images for a frame size -------------------------------------------------------------
Status = Literal["ok", "scaled", "refused", "missing", "changed", "unknown"]


@dataclass(frozen=True)
class ImageCheck:
    """One image, checked for one frame size (a row of ``fovexp stimuli check``)."""

    id: str
    kind: Literal["scene", "frame", "unknown"]
    path: Path | None
    #: the file's size (None when there is no file)
    size: Size | None
    #: the size the session shows it at
    frame_size: Size
    #: ok (file bytes), ok (pixels) (same pixels, other PNG bytes), changed, missing, unpinned
    sha: str
    status: Status
    #: what is wrong, one line (None when usable)
    problem: str | None = None
    #: the command or step that fixes it
    fix: str | None = None
    #: the file's sha256 (recorded in the session file)
    sha256: str | None = None

    @property
    def usable(self) -> bool:
        return self.status in ("ok", "scaled")

    @property
    def scaled(self) -> bool:
        return self.status == "scaled"

    def record(self) -> dict[str, Any]:
        """What the session file keeps of it."""
        out: dict[str, Any] = {"kind": self.kind, "path": str(self.path), "sha256": self.sha256,
                               "size": list(self.size) if self.size else None}
        if self.scaled:
            out["scaled_to"] = list(self.frame_size)
        return out


class StimulusSet:
    """The shipped scene pins and a stimulus folder's manifest, combined: ids to checked files.

    A lab's id may not be a generated scene's. Reading it writes nothing; the folder is
    written by :func:`generate_scenes` and :meth:`write_manifest` (``fovexp stimuli generate``
    and ``add``).
    """

    def __init__(self, folder: Path, manifest_path: Path | None = None, found_by: str = "",
                 scene_pins: dict[str, SceneEntry] | None = None) -> None:
        self.folder = Path(folder)
        self.manifest_path = Path(manifest_path) if manifest_path else self.folder / MANIFEST
        self.found_by = found_by
        self.scenes = scene_pins if scene_pins is not None else load_scene_pins()
        self.lab = LabManifest()
        if self.manifest_path.is_file():
            data = read_yaml(self.manifest_path, "stimulus manifest")
            try:
                self.lab = LabManifest.model_validate(data or {})
            except ValidationError as exc:
                raise validation_error(f"stimulus manifest {self.manifest_path}", exc) from None
        self.frames: dict[str, StimulusEntry] = {}
        for e in self.lab.images:
            if e.id in self.frames:
                raise FovexpError(f"stimulus manifest {self.manifest_path}: duplicate id "
                                  f"{e.id!r}")
            if e.id in self.scenes:
                raise FovexpError(f"stimulus manifest {self.manifest_path}: id {e.id!r} is a "
                                  "generated scene's; give the frame another id")
            self.frames[e.id] = e
        for res, by_id in self.lab.generated.items():
            if re.fullmatch(_WXH, res) is None or not set(by_id) <= set(self.scenes):
                raise FovexpError(f"stimulus manifest {self.manifest_path}: generated.{res}: "
                                  "expected a size WxH and generated scene ids")

    @classmethod
    def find(cls, explicit: str | Path | None = None, protocol_key: str | None = None,
             protocol_dir: Path | None = None) -> StimulusSet:
        folder, manifest, how = find_folder(explicit, protocol_key, protocol_dir)
        return cls(folder, manifest, how)

    def __contains__(self, image_id: str) -> bool:
        return image_id in self.scenes or image_id in self.frames

    @property
    def ids(self) -> list[str]:
        return [*self.scenes, *self.frames]

    def describe(self) -> str:
        return f"{self.folder} (found by {self.found_by})" if self.found_by else str(self.folder)

    # -- generated scenes ----------------------------------------------------------------------
    def scene_path(self, image_id: str, size: Size) -> Path:
        return self.folder / GENERATED / size_text(size) / f"{image_id}.png"

    def scene_pin(self, image_id: str, size: Size) -> Pin | None:
        """The shipped pin at ``size``, else the one this folder recorded when it generated
        the scene at a resolution fovexp does not pin."""
        shipped = self.scenes[image_id].sha256.get(size_text(size))
        return shipped or self.lab.generated.get(size_text(size), {}).get(image_id)

    def pinned_sizes(self, image_id: str) -> list[Size]:
        res = set(self.scenes[image_id].sha256)
        res |= {r for r, ids in self.lab.generated.items() if image_id in ids}
        return sorted((tuple(int(v) for v in r.split("x")) for r in res),  # type: ignore[misc]
                      key=lambda s: (s[0] * s[1], s))

    def generate_command(self, size: Size) -> str:
        return f"fovexp stimuli generate --size {size_text(size)} --stimuli {self.folder}"

    def verify_scene(self, image_id: str, size: Size, path: Path) -> tuple[str, str]:
        """(sha status, file sha256) of a generated scene's file: ``ok`` when its bytes are
        the pinned ones, ``ok (pixels)`` when its pixels are (another zlib wrote it),
        ``changed``, or ``unpinned`` when no sha256 is recorded for this resolution."""
        digest = _cached_sha256(path)
        pin = self.scene_pin(image_id, size)
        if pin is None:
            return "unpinned", digest
        if digest == pin.file:
            return "ok", digest
        try:
            pixels = scenes.pixels_sha256(read_samples(path))
        except FovexpError:
            return "changed", digest
        return ("ok (pixels)" if pixels == pin.pixels else "changed"), digest

    # -- checks --------------------------------------------------------------------------------
    def check(self, image_id: str, frame_size: Size, dry_run: bool) -> ImageCheck:
        """Whether a session with frames of ``frame_size`` can show ``image_id``: a real one
        only at exactly that size, a dry run also scaled. Never raises for a bad file."""
        if image_id in self.scenes:
            return self._check_scene(image_id, frame_size, dry_run)
        if image_id in self.frames:
            return self._check_frame(image_id, frame_size, dry_run)
        hint = did_you_mean(image_id, self.ids, n=2)
        return ImageCheck(image_id, "unknown", None, None, frame_size, "-", "unknown",
                          f"image {image_id!r} is neither a generated scene "
                          f"({scenes.SCENE_IDS[0]} ... {scenes.SCENE_IDS[-1]}) nor in "
                          f"{self.manifest_path}{hint}",
                          "fix the id" + hint if hint else
                          "add it with: fovexp stimuli add IMAGE --id ID, or fix the id")

    def _check_scene(self, image_id: str, frame_size: Size, dry_run: bool) -> ImageCheck:
        size = frame_size
        if dry_run and not self.scene_path(image_id, size).is_file():
            # a dry run may scale: the smallest generated resolution at least as large as its
            # window, else the largest there is
            present = [s for s in self.pinned_sizes(image_id)
                       if self.scene_path(image_id, s).is_file()]
            larger = [s for s in present if s[0] >= size[0] and s[1] >= size[1]]
            if present:
                size = larger[0] if larger else present[-1]
        path = self.scene_path(image_id, size)
        if not path.is_file():
            need = frame_size if (not dry_run or frame_size in PINNED) else DRY_RUN_SIZE
            return ImageCheck(image_id, "scene", path, None, frame_size, "missing", "missing",
                              f"generated scene {image_id!r} at {size_text(frame_size)} is "
                              f"not in {self.folder / GENERATED}",
                              self.generate_command(need))
        sha, digest = self.verify_scene(image_id, size, path)
        if sha in ("unpinned", "changed"):
            why = (f"no sha256 is recorded for {image_id} at {size_text(size)}"
                   if sha == "unpinned" else
                   f"it is not the generated {image_id} (sha256 {digest[:12]}...)")
            return ImageCheck(image_id, "scene", path, size, frame_size, sha, "changed",
                              f"{path}: {why}", self.generate_command(size) + " --force",
                              digest)
        return self._sized(image_id, "scene", path, image_size(path), frame_size, sha, digest,
                           dry_run)

    def _check_frame(self, image_id: str, frame_size: Size, dry_run: bool) -> ImageCheck:
        e = self.frames[image_id]
        p = Path(e.path).expanduser()
        path = p if p.is_absolute() else (self.manifest_path.parent / p).resolve()
        if not path.is_file():
            return ImageCheck(image_id, "frame", path, None, frame_size, "missing", "missing",
                              f"image {image_id!r}: file {path} is missing",
                              f"restore it, or add it again: fovexp stimuli add FILE --id "
                              f"{image_id} --replace --stimuli {self.folder}")
        digest = _cached_sha256(path)
        if digest != e.sha256:
            return ImageCheck(image_id, "frame", path, None, frame_size, "changed", "changed",
                              f"image {image_id!r}: {path} has sha256 {digest[:12]}..., the "
                              f"manifest {self.manifest_path} records {e.sha256[:12]}... "
                              "(file changed?)",
                              f"restore the file, or add it again with --replace "
                              f"(fovexp stimuli add FILE --id {image_id} --replace)", digest)
        actual = image_size(path)
        return self._sized(image_id, "frame", path, actual, frame_size, "ok", digest, dry_run)

    def _sized(self, image_id: str, kind: Literal["scene", "frame"], path: Path, actual: Size,
               frame_size: Size, sha: str, digest: str, dry_run: bool) -> ImageCheck:
        if actual == frame_size:
            return ImageCheck(image_id, kind, path, actual, frame_size, sha, "ok",
                              sha256=digest)
        if dry_run:
            return ImageCheck(image_id, kind, path, actual, frame_size, sha, "scaled",
                              sha256=digest)
        fix = (self.generate_command(frame_size) if kind == "scene" else
               f"export it at {size_text(frame_size)} and add it again (fovexp stimuli add "
               f"FILE --id {image_id} --replace)")
        return ImageCheck(image_id, kind, path, actual, frame_size, sha, "refused",
                          f"image {image_id!r} ({path}) is {size_text(actual)}; the display "
                          f"shows {size_text(frame_size)} (a real session never rescales a "
                          "stimulus)", fix, digest)

    def check_all(self, ids: list[str], frame_size: Size, dry_run: bool) -> list[ImageCheck]:
        return [self.check(i, frame_size, dry_run) for i in ids]

    def require(self, ids: list[str], frame_size: Size, dry_run: bool,
                where: str) -> dict[str, ImageCheck]:
        """Every image checked; raises FovexpError (one line: the first problem, its fix, and
        how many more there are) unless all are usable."""
        rows = self.check_all(ids, frame_size, dry_run)
        bad = [(k, r) for k, r in enumerate(rows) if not r.usable]
        if bad:
            k, r = bad[0]
            more = (f"; {len(bad) - 1} more image(s) too (fovexp stimuli check lists them)"
                    if len(bad) > 1 else "")
            raise FovexpError(f"{where}: images[{k}]: {r.problem}; to fix: {r.fix}{more}")
        return {r.id: r for r in rows}

    # -- writing (fovexp stimuli generate / add) -----------------------------------------------
    def write_manifest(self) -> None:
        """Write the folder's manifest atomically (a header comment, then the entries)."""
        data = self.lab.model_dump(exclude_defaults=False)
        if not data["generated"]:
            del data["generated"]
        text = MANIFEST_HEADER + yaml.safe_dump(data, sort_keys=False, width=100)
        write_bytes_atomic(self.manifest_path, text.encode())


# -- generating the scenes ------------------------------------------------------------------------
@dataclass
class Generated:
    """What :func:`generate_scenes` did."""

    size: Size
    folder: Path
    written: list[str]
    up_to_date: list[str]
    n_bytes: int
    seconds: float
    jobs: int
    #: a resolution fovexp does not pin: the sha256 went into the folder's manifest
    recorded: bool
    #: written with other PNG bytes than the pinned ones (same pixels: another zlib)
    other_zlib: list[str]


def _render_png(index: int, size: Size) -> tuple[bytes, str]:
    """One scene's PNG bytes and pixel hash (in a worker process when there are several)."""
    pixels = scenes.render_scene(index, *size)
    return scenes.png_bytes(pixels), scenes.pixels_sha256(pixels)


def generate_scenes(stim: StimulusSet, size: Size, ids: list[str] | None = None,
                    force: bool = False, jobs: int = 1,
                    progress: Any = None, on_todo: Any = None) -> Generated:
    """Write the generated scenes ``ids`` (default: all) at ``size`` into the folder of
    ``stim``; a file that checks out is kept unless ``force``. At a pinned resolution every
    scene's pixels must hash to the pin (else nothing is written for it and FovexpError says
    so); at any other its sha256 are recorded in the folder's manifest. ``progress(id,
    n_bytes, sha256)`` is called after each file, ``on_todo(ids)`` once before the first with
    the scenes to draw (those that check out are left out)."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    ids = list(scenes.SCENE_IDS) if ids is None else ids
    unknown = [i for i in ids if i not in scenes.SCENE_IDS]
    if unknown:
        raise FovexpError(f"{', '.join(unknown)}: not generated scenes "
                          f"({scenes.SCENE_IDS[0]} ... {scenes.SCENE_IDS[-1]})")
    if jobs < 1:
        raise FovexpError("jobs must be at least 1")
    todo, kept = [], []
    for i in ids:
        path = stim.scene_path(i, size)
        ok = path.is_file() and not force and stim.verify_scene(i, size, path)[0].startswith("ok")
        (kept if ok else todo).append(i)
    if on_todo is not None:
        on_todo(todo)
    t0 = time.perf_counter()
    out = Generated(size, stim.folder / GENERATED / size_text(size), [], kept, 0, 0.0,
                    min(jobs, max(1, len(todo))), False, [])
    indices = [scenes.SCENE_IDS.index(i) for i in todo]
    if out.jobs > 1:
        pool = ProcessPoolExecutor(max_workers=out.jobs)
        results = pool.map(_render_png, indices, [size] * len(todo))
    else:
        pool, results = None, map(_render_png, indices, [size] * len(todo))
    try:
        for image_id, (data, pixels) in zip(todo, results, strict=True):
            pin = stim.scenes[image_id].sha256.get(size_text(size))
            digest = hashlib.sha256(data).hexdigest()
            if pin is not None and pixels != pin.pixels:
                import PIL

                raise FovexpError(
                    f"{image_id} at {size_text(size)}: the generator's pixels differ from the "
                    f"pinned ones (sha256 {pixels[:12]}... vs {pin.pixels[:12]}...; numpy "
                    f"{np.__version__}, Pillow {PIL.__version__}): this machine does not "
                    "reproduce the scenes, and nothing was written for it (please report it)")
            if pin is not None and digest != pin.file:
                out.other_zlib.append(image_id)
            write_bytes_atomic(stim.scene_path(image_id, size), data)
            if pin is None:
                stim.lab.generated.setdefault(size_text(size), {})[image_id] = Pin(
                    file=digest, pixels=pixels)
                out.recorded = True
            out.written.append(image_id)
            out.n_bytes += len(data)
            if progress is not None:
                progress(image_id, len(data), digest)
    finally:
        if out.recorded:  # what was written is recorded, even when a later scene failed
            res = size_text(size)
            stim.lab.generated[res] = dict(sorted(stim.lab.generated[res].items()))
            stim.write_manifest()
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    out.seconds = time.perf_counter() - t0
    return out


# -- images for the session ----------------------------------------------------------------------
def load_stimulus(path: Path, size: Size, scale: bool = False) -> np.ndarray:
    """Read an image as display-encoded float32 RGB in [0, 1] of ``size = (width, height)``.

    A file of another size is an error unless ``scale`` (dry runs only: the enhancer then
    sees a smaller image on the same physical screen), which resizes it with Pillow's box
    filter (area averaging). A real session never gets here with another size: the protocol's
    images are checked before its window opens (:meth:`StimulusSet.require`)."""
    from fovexp import read_image  # the enhancer's public reader (docs/API.md)

    img = np.asarray(read_image(path), dtype=np.float32)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3]
    if (img.shape[1], img.shape[0]) != tuple(size):
        if not scale:
            raise FovexpError(f"{path} is {img.shape[1]}x{img.shape[0]}, the window shows "
                              f"{size_text(size)}: a real session never rescales a stimulus")
        img = resize_area(img, size)
    return img


def resize_area(img: np.ndarray, size: Size) -> np.ndarray:
    """Resize with Pillow's box filter on the display-encoded values (a dry run's preview, not
    a measurement)."""
    from PIL import Image

    w, h = size
    chans = [
        np.asarray(Image.fromarray(np.ascontiguousarray(img[..., c], dtype=np.float32)).resize(
            (w, h), Image.Resampling.BOX))
        for c in range(img.shape[2])
    ]
    return np.clip(np.stack(chans, axis=2), 0.0, 1.0).astype(np.float32)


def split_screen(reference: np.ndarray) -> np.ndarray:
    """The frame the enhancer processes (paper section 5.1, "Task"): the reference's left half on
    the left and its mirror image on the right, meeting at the screen centre where the fixation
    cross is. Width must be even so the seam is exactly at the centre."""
    h, w = reference.shape[:2]
    if w % 2:
        raise FovexpError(f"stimulus width {w} px must be even (the seam is the screen centre)")
    left = reference[:, : w // 2]
    return np.ascontiguousarray(np.concatenate([left, left[:, ::-1]], axis=1))


# -- maintainers: pinning ------------------------------------------------------------------------
def pin_scenes(sizes: list[Size], path: Path | None = None) -> None:
    """Render every scene at ``sizes`` and write their sha256 into the shipped ``scenes.yaml``
    (in the project's clone: ``stimuli/scenes.yaml``). Other resolutions' pins are kept."""
    path = path or _shipped_pins_path()
    old = load_scene_pins(path) if path.is_file() else {}
    entries = []
    for spec in scenes.SCENES:
        prev = old.get(spec.id)
        pins = dict(prev.sha256) if prev else {}
        for size in sizes:
            pixels = scenes.render_scene(spec.index, *size)
            data = scenes.png_bytes(pixels)
            pins[size_text(size)] = Pin(file=hashlib.sha256(data).hexdigest(),
                                        pixels=scenes.pixels_sha256(pixels))
            print(f"{spec.id} {size_text(size)}: {len(data) / 1e6:.1f} MB "
                  f"{pins[size_text(size)].file}")
        entries.append(SceneEntry(
            id=spec.id, description=spec.describe(),
            source="fovexp.stimuli.scenes (synthetic, deterministic)", licence="CC0-1.0",
            sha256=dict(sorted(pins.items(), key=lambda kv: -int(kv[0].split("x")[0])))))
    import zlib

    import png

    header = (
        "# The generated scenes (fovexp.stimuli.scenes) and the sha256 of their PNG file and\n"
        "# of their pixels at each pinned resolution. Written by\n"
        "#   python -m fovexp.stimuli.folder 3840x2160 480x270\n"
        "# whenever the generator changes; `fovexp stimuli generate` checks its output here.\n"
        f"# PNG bytes of pypng {png.__version__} with zlib {zlib.ZLIB_RUNTIME_VERSION}, level "
        f"{scenes.PNG_LEVEL}.\n")
    text = header + yaml.safe_dump(ScenePins(scenes=entries).model_dump(), sort_keys=False,
                                   width=100)
    write_bytes_atomic(path, text.encode())


if __name__ == "__main__":
    import sys

    pin_scenes([parse_size(a) for a in sys.argv[1:]] or list(PINNED))
