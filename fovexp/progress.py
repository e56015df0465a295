"""Progress of long steps, on stderr: a tqdm bar in a terminal, plain lines in a log.

Every step that can take more than a few seconds (``fovexp compile``, ``fovexp stimuli
generate``, a session's preparation, a 4K ``fovexp enhance --dump-maps``, the evaluation
commands) reports through :func:`progress_bar` or :class:`Steps`, so that a lab never faces minutes
of silence (docs/STUDY.md, "Progress"). In a terminal tqdm redraws one line; when stderr is not a
terminal (CI logs, ``2> file``, a pipe), tqdm's ``\\r`` redraws would pile up into one endless
line, so each update is written as its own line instead, at most one every
:data:`LOG_INTERVAL_S` seconds besides the first and the last. stdout stays for results.
``FOVEXP_PROGRESS=0`` turns progress off.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from typing import IO, Any, TypeVar

T = TypeVar("T")

#: seconds between two progress lines in a log (a terminal's bar redraws freely)
LOG_INTERVAL_S = 5.0


class _Lines:
    """A stream for tqdm that turns each redraw (``\\r`` + the bar) into one line."""

    def __init__(self, stream: IO[str]) -> None:
        self.stream = stream

    def write(self, text: str) -> None:
        text = text.replace("\r", "").rstrip()
        if text:
            self.stream.write(text + "\n")

    def flush(self) -> None:
        self.stream.flush()


def enabled() -> bool:
    """Whether progress is shown (``FOVEXP_PROGRESS=0`` turns it off)."""
    return os.environ.get("FOVEXP_PROGRESS", "1") != "0"


def progress_bar(iterable: Iterable[T] | None = None, *, total: int | None = None, desc: str,
             unit: str = "it", stream: IO[str] | None = None, bar_format: str | None = None,
             ) -> Any:
    """A tqdm progress bar over ``iterable`` (or updated by hand: ``.update(n)``) on stderr,
    in the form that suits it (the module docstring)."""
    from tqdm import tqdm  # type: ignore[import-untyped]

    stream = sys.stderr if stream is None else stream
    tty = hasattr(stream, "isatty") and stream.isatty()
    kwargs: dict[str, Any] = {"desc": desc, "unit": unit, "total": total,
                              "disable": not enabled(), "dynamic_ncols": tty,
                              "bar_format": bar_format}
    if tty:
        kwargs["file"] = stream
    else:
        kwargs.update(file=_Lines(stream), mininterval=LOG_INTERVAL_S, ascii=True, ncols=140)
    return tqdm(iterable, **kwargs)


class Steps:
    """Named steps of one long job, each shown as it starts (in a log too: one line each), so
    a slow step is seen by its name::

        with Steps(["read", "enhance", "write"], desc="enhance") as step:
            step("read")
            ...
            step("enhance")
    """

    def __init__(self, names: Iterable[str], *, desc: str, stream: IO[str] | None = None
                 ) -> None:
        self.names = list(names)
        self.bar = progress_bar(total=len(self.names), desc=desc, unit="step", stream=stream,
                            bar_format="{desc}: {n_fmt}/{total_fmt} steps [{elapsed}]{postfix}")
        self.started = 0

    def __call__(self, name: str, detail: str | None = None) -> None:
        """Start step ``name``; called again for the step under way with a ``detail`` (a
        part of it: ``step("maps", "sigma_px")``), show that part."""
        if name not in self.names:
            raise ValueError(f"step {name!r} is not one of {self.names}")
        if not (self.started and self.names[self.started - 1] == name):
            self.bar.n = self.started  # the steps before it are done
            self.started += 1
        self.bar.set_postfix_str(name if detail is None else f"{name}: {detail}", refresh=True)

    def __enter__(self) -> Steps:
        return self

    def __exit__(self, exc_type: object, *_: object) -> None:
        if exc_type is None:
            self.bar.n = len(self.names)
            self.bar.set_postfix_str("done", refresh=False)
        self.bar.close()
