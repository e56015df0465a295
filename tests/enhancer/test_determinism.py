"""Same seed, same bytes: the output of ``fovexp enhance`` does not depend on how its kernels
were compiled (in the process that runs them, loaded from Numba's cache, ahead of time by
``fovexp compile``) nor on the number of threads (issue 10: the first run after installing
differed from every later one by 1 LSB in ~700 pixels of a 4K frame; fovexp/jit.py has the
cause). Each run is a fresh process with its own ``NUMBA_CACHE_DIR``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from fovexp.jit import FASTMATH

from engine_helpers import textured_image

# The CLI writes the frame (16-bit PNG); the API's float32 output and noise of the same call
# are hashed too, so that a difference below a 16-bit step is caught as well.
SCRIPT = r"""
import hashlib, json, sys
import numpy as np
from fovexp import load_display, make_enhancer, make_params, read_image
from fovexp.cli import main
from fovexp.warmup import kernels

src, out = sys.argv[1:3]
rc = main(["enhance", src, out, "--impulses", "12", "--seed", "3", "--blur-rate", "0.57",
           "--backend", "cpu", "--bit-depth", "16"])
enh = make_enhancer(load_display("lg-oled55cx"), backend="cpu")
enh.set_image(read_image(src))
res = enh.enhance((0.5, 0.5), make_params(impulses=12, seed=3, blur_rate=0.57))
digest = lambda b: hashlib.sha256(b).hexdigest()
print(json.dumps({
    "rc": rc,
    "file": digest(open(out, "rb").read()),
    "output": digest(np.ascontiguousarray(res.output).tobytes()),
    "noise": digest(np.ascontiguousarray(res.map("noise")).tobytes()),
    "compiled": sorted(n for n, d in kernels().items() if d.stats.cache_misses),
}))
"""


def _env(cache_dir, threads: int) -> dict[str, str]:
    return {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), "NUMBA_NUM_THREADS": str(threads)}


def _start_enhance(src, out, cache_dir, threads: int) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", SCRIPT, str(src), str(out)],
                            env=_env(cache_dir, threads), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _result(proc: subprocess.Popen) -> dict:
    stdout, stderr = proc.communicate(timeout=900)
    assert proc.returncode == 0, stderr
    result = json.loads(stdout.strip().splitlines()[-1])
    assert result["rc"] == 0
    return result


def _enhance(src, out, cache_dir, threads: int) -> dict:
    return _result(_start_enhance(src, out, cache_dir, threads))


def test_kernels_are_compiled_without_fast_math():
    """The cause (fovexp/jit.py): no kernel is compiled with fast-math (no flag of it either),
    whose reassociation and FMA fusion let two compilations of one loop differ. The engine's
    kernels say so with ``fastmath=FASTMATH``; a kernel of the runner may leave the flag out
    (it may not import fovexp.jit), which is the same."""
    from fovexp.warmup import _import_kernel_modules, kernels

    assert FASTMATH is False
    _import_kernel_modules()  # every module that defines a kernel
    found = kernels()
    assert len(found) >= 10
    for name, disp in found.items():
        assert not disp.targetoptions.get("fastmath", False), name
        if not name.startswith(("fovexp.experiment.", "fovexp.analysis.")):
            assert "fastmath" in disp.targetoptions, name  # the engine's say it explicitly


@pytest.mark.slow  # compiles every kernel twice, in fresh caches
def test_same_seed_same_bytes_however_the_kernels_were_compiled(tmp_path):
    src = tmp_path / "frame.png"
    iio.imwrite(src, np.round(textured_image(270, 480, seed=5) * 255).astype(np.uint8))
    fresh, ahead = tmp_path / "cache-fresh", tmp_path / "cache-ahead"
    fresh.mkdir()
    ahead.mkdir()
    # The two compilations run side by side: Numba compiles on one thread, so on CI's two
    # cores this halves the test's time. Nothing in the outputs depends on it.
    # Nothing in the cache: this process compiles every kernel it calls ...
    here = _start_enhance(src, tmp_path / "a.png", fresh, threads=2)
    # ... and what ./dev setup does (fovexp compile), into its own cache
    # (its output into files: a full pipe would stall it while the other run is awaited)
    log_out, log_err = tmp_path / "compile.out", tmp_path / "compile.err"
    with open(log_out, "w") as out, open(log_err, "w") as err:
        compile_ = subprocess.Popen([sys.executable, "-m", "fovexp", "compile"],
                                    env={**_env(ahead, 2), "FOVEXP_PROGRESS": "1"},
                                    stdout=out, stderr=err, text=True)
    runs = {"compiled here": _result(here)}
    compile_.wait(timeout=900)
    stdout, stderr = log_out.read_text(), log_err.read_text()
    assert compile_.returncode == 0, stderr
    # the same folder again: every kernel comes from the cache
    runs["cached"] = _enhance(src, tmp_path / "b.png", fresh, threads=2)
    runs["cached, 1 thread"] = _enhance(src, tmp_path / "c.png", fresh, threads=1)
    # its counts add up (issue 32): every kernel compiled, loaded or inside its callers
    counts = re.search(r"(\d+) kernels: (\d+) compiled, (\d+) loaded from the cache, (\d+) "
                       r"inside the kernels that call them", stdout)
    assert counts, stdout
    total, compiled, loaded, inlined = map(int, counts.groups())
    assert compiled > 0 and compiled + loaded + inlined == total
    assert f"{total}/{total}" in stderr  # the progress reached its total, in a log
    # the first run after fovexp compile
    runs["compiled by fovexp compile"] = _enhance(src, tmp_path / "d.png", ahead, threads=2)

    assert runs["compiled here"]["compiled"]  # the scenario holds: that run compiled ...
    for name in ("cached", "cached, 1 thread", "compiled by fovexp compile"):
        assert runs[name]["compiled"] == [], name  # ... and these compiled nothing
    first = runs["compiled here"]
    for name, run in runs.items():
        for key in ("file", "output", "noise"):
            assert run[key] == first[key], (name, key)
