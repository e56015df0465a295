"""The stimulus manifest (``stimuli/manifest.yaml``) and the trial images built from it.

Protocols name images by id; the manifest maps an id to a file, its source and licence, and a
sha256 that is checked when the protocol is loaded, so a run never silently uses a different
frame than the one that was calibrated on (paper section 6.1, "Stimuli").
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fovexp import FovexpError, read_yaml, validation_error


class StimulusEntry(BaseModel):
    """One manifest entry."""

    model_config = ConfigDict(extra="forbid")
    id: str = Field(pattern=r"^[A-Za-z0-9_.-]{1,64}$")
    path: str
    source: str
    licence: str
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")


class Manifest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    images: list[StimulusEntry] = Field(min_length=1)


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class StimulusSet:
    """A loaded manifest: ``resolve(id)`` gives a checked path."""

    def __init__(self, manifest_path: Path) -> None:
        self.path = Path(manifest_path)
        data = read_yaml(self.path, "stimulus manifest")
        try:
            self.manifest = Manifest.model_validate(data)
        except ValidationError as exc:
            raise validation_error(f"stimulus manifest {self.path}", exc) from None
        self.entries: dict[str, StimulusEntry] = {}
        for e in self.manifest.images:
            if e.id in self.entries:
                raise FovexpError(f"stimulus manifest {self.path}: duplicate id {e.id!r}")
            self.entries[e.id] = e

    def file_of(self, image_id: str) -> Path:
        return (self.path.parent / self.entries[image_id].path).resolve()

    def check(self, image_id: str, where: str) -> Path:
        """The image's path after checking it is listed, present and unchanged.

        ``where`` names the referring file and key for the error message.
        """
        if image_id not in self.entries:
            raise FovexpError(f"{where}: image {image_id!r} is not in {self.path}")
        path = self.file_of(image_id)
        if not path.is_file():
            raise FovexpError(f"{where}: image {image_id!r}: file {path} is missing")
        digest = sha256_file(path)
        if digest != self.entries[image_id].sha256:
            raise FovexpError(
                f"{where}: image {image_id!r}: {path} has sha256 {digest[:12]}..., the manifest "
                f"{self.path} records {self.entries[image_id].sha256[:12]}... (file changed?)"
            )
        return path


def load_stimulus(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Read an image as display-encoded float32 RGB in [0, 1], optionally resized to
    ``size = (width, height)`` (area averaging; dry runs use small frames, issue item 6)."""
    from fovexp import read_image  # the enhancer's public reader (docs/API.md)

    img = np.asarray(read_image(path), dtype=np.float32)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    img = img[..., :3]
    if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
        img = resize_area(img, size)
    return img


def resize_area(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Resize with Pillow's box filter on the display-encoded values (a stimulus preview, not a
    measurement: the enhancer then sees a smaller image on the same physical screen)."""
    from PIL import Image

    w, h = size
    chans = [
        np.asarray(Image.fromarray(np.ascontiguousarray(img[..., c], dtype=np.float32)).resize(
            (w, h), Image.Resampling.BOX))
        for c in range(img.shape[2])
    ]
    return np.clip(np.stack(chans, axis=2), 0.0, 1.0).astype(np.float32)


def split_screen(reference: np.ndarray) -> np.ndarray:
    """The frame the enhancer processes (paper section 6.1, "Task"): the reference's left half on
    the left and its mirror image on the right, meeting at the screen centre where the fixation
    cross is. Width must be even so the seam is exactly at the centre."""
    h, w = reference.shape[:2]
    if w % 2:
        raise FovexpError(f"stimulus width {w} px must be even (the seam is the screen centre)")
    left = reference[:, : w // 2]
    return np.ascontiguousarray(np.concatenate([left, left[:, ::-1]], axis=1))
