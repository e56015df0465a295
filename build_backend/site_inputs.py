"""What the documentation site is built from, as one digest (standard library only).

The wheel's build backend (``build_backend/fovexp_build.py``) and the site's MkDocs hook
(``docs/_mkdocs/hooks.py``) both call :func:`site_inputs_digest`: the hook stamps the packed site
(``fovexp/site.zip``) with it, and the backend rebuilds the site only when the stamp is not the
digest of the tree it builds. One definition, so that the two never disagree on "up to date".
"""

from __future__ import annotations

import hashlib
from pathlib import Path

#: the stamp's prefix in the zip file's comment
STAMP_PREFIX = b"fovexp-site-inputs:"


def site_input_files(root: Path) -> list[Path]:
    """The files the site is made of: its configuration, every file under docs/ (the pages,
    their images, the hooks) and the package's Python sources (the API reference is rendered
    from their docstrings). docs/STATUS.md is left out, as the site leaves it out."""
    files = [root / "mkdocs.yml"]
    files += [p for p in (root / "docs").rglob("*")
              if p.is_file() and p.name != "STATUS.md" and "__pycache__" not in p.parts]
    files += [p for p in (root / "fovexp").rglob("*.py") if "__pycache__" not in p.parts]
    return sorted(files)


def site_inputs_digest(root: Path) -> str:
    """sha256 over the relative path and bytes of each of :func:`site_input_files`."""
    h = hashlib.sha256()
    for path in site_input_files(root):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def packed_stamp(site_zip: Path) -> str | None:
    """The digest a packed site was stamped with, or None (no zip, or no stamp)."""
    import zipfile

    if not site_zip.is_file():
        return None
    try:
        with zipfile.ZipFile(site_zip) as zf:
            comment = zf.comment
    except zipfile.BadZipFile:
        return None
    if not comment.startswith(STAMP_PREFIX):
        return None
    return comment[len(STAMP_PREFIX):].decode("ascii", "replace")
