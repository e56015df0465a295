"""The render thread's side of the display loop, without a window: 8-bit RGBA for the upload,
which renders reach the screen (a dropped one never; an older one while a newer is computed),
the GPU backend's output written into a texture GPU-side, and why ``auto`` chose the CPU."""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

import fovexp
from fovexp import FovexpError, load_display, make_enhancer, make_params
from fovexp.backends import NO_GPU_DEVICE, gpu_device_present
from fovexp.experiment.display.render import TestRenderer, to_rgba8

DISPLAY = load_display("lg-oled55cx")


def test_to_rgba8_rounds_to_the_nearest_level() -> None:
    levels = np.arange(256) / 255.0
    img = np.stack([levels, levels[::-1], np.full(256, 0.5)], axis=-1)[None].astype(np.float32)
    out = to_rgba8(img)
    assert out.dtype == np.uint8 and out.shape == (1, 256, 4)
    assert (out[0, :, 0] == np.arange(256)).all() and (out[0, :, 1] == np.arange(256)[::-1]).all()
    assert (out[..., 2] == 128).all() and (out[..., 3] == 255).all()  # 127.5 rounds up
    # just below and above a half level, out of range, NaN; grey images fill R, G and B
    odd = np.array([[0.5 / 255 - 1e-4, 0.5 / 255 + 1e-4, -0.2, 1.3, np.nan]], np.float32)
    assert to_rgba8(odd)[0, :, 0].tolist() == [0, 1, 0, 255, 0]
    assert (to_rgba8(odd)[..., 1] == to_rgba8(odd)[..., 0]).all()
    with pytest.raises(FovexpError, match="expected"):
        to_rgba8(np.zeros((4, 4, 2)))


class Gated:
    """An enhancer whose renders wait for a go-ahead, one per call: the test decides when each
    render finishes."""

    backend = "fake"

    def __init__(self, *a, **kw) -> None:
        self.go = threading.Semaphore(0)
        self.started = threading.Semaphore(0)

    def set_image(self, image, viewport=None, **kw) -> None:
        self.shape = image.shape

    def enhance(self, gaze, params):
        self.started.release()
        assert self.go.acquire(timeout=10)

        class Res:
            output = np.full(self.shape, params.f_e, np.float32)

        res = Res()
        res.params = params
        return res


def test_dropped_render_never_reaches_the_screen(monkeypatch) -> None:
    """A render under way when the frame loop drops it (Enter) finishes unseen; a render of an
    older request is shown while a newer one is computed (the wheel is seen moving)."""
    enh = Gated()
    monkeypatch.setattr(fovexp, "make_enhancer", lambda *a, **kw: enh)
    r = TestRenderer(DISPLAY)
    try:
        r.set_image(np.zeros((8, 8, 3), np.float32), (16, 8))
        r.request(make_params(method="contrast", blur_rate=0.3, f_e=0.1))
        assert enh.started.acquire(timeout=10)
        r.request(make_params(method="contrast", blur_rate=0.3, f_e=0.2))  # newer, queued
        enh.go.release()
        deadline = time.monotonic() + 10
        got = None
        while got is None and time.monotonic() < deadline:
            got = r.poll()
            time.sleep(0.005)
        assert got is not None and got.params.f_e == 0.1  # the older one, shown meanwhile
        assert enh.started.acquire(timeout=10)  # the newer one is under way ...
        r.drop_pending()  # ... when Enter comes
        enh.go.release()
        time.sleep(0.2)
        assert r.poll() is None
    finally:
        enh.go.release()
        r.close()


def test_auto_says_why_it_chose_the_cpu() -> None:
    """``auto`` takes the GPU on a hardware renderer and says why it took the CPU otherwise;
    which one is expected comes from the renderer's name and a list written down
    (tests/gpu_helpers.py), not from fovexp's own ``is_software`` (issue 19)."""
    from gpu_helpers import renders_in_software

    assert make_enhancer(DISPLAY, backend="cpu").fallback_reason is None
    rel = make_enhancer(DISPLAY, preset="release", backend="auto")
    assert rel.backend == "cpu" and "release" in rel.fallback_reason
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=450)
    except Exception:
        renderer = None  # no OpenGL 4.5 here: the CPU, for that reason
    else:
        renderer = ctx.info["GL_RENDERER"]
        ctx.release()
    auto = make_enhancer(DISPLAY, backend="auto")
    if renderer is not None and not renders_in_software(renderer):  # a hardware GPU
        assert auto.backend == "gpu" and auto.fallback_reason is None
        auto.close()
    elif renderer is not None and not gpu_device_present():  # llvmpipe, no GPU device: CI
        assert auto.backend == "cpu" and auto.fallback_reason == NO_GPU_DEVICE
    elif renderer is not None:  # llvmpipe beside a device it cannot use
        assert auto.backend == "cpu"
        assert auto.fallback_reason.startswith("the OpenGL renderer is software")
        assert renderer in auto.fallback_reason
    else:
        assert auto.backend == "cpu" and auto.fallback_reason.startswith("no GPU")


def test_auto_skips_the_context_where_linux_shows_no_gpu_device(monkeypatch, tmp_path) -> None:
    """On Linux without a GPU device file, ``auto`` takes the CPU without making an OpenGL
    context (it would be Mesa's software renderer); with one, it makes the context and judges
    it (here: llvmpipe, or a hardware GPU)."""
    import fovexp.backends as backends

    pytest.importorskip("moderngl")
    if not sys.platform.startswith("linux"):
        assert gpu_device_present()
        return
    monkeypatch.setattr(backends, "_GPU_DEVICE_FILES", (str(tmp_path / "renderD*"),))
    assert not gpu_device_present()
    made = []
    monkeypatch.setattr("fovexp.gpu.create_context", lambda ctx=None: made.append(ctx))
    auto = make_enhancer(DISPLAY, backend="auto")
    assert auto.backend == "cpu" and auto.fallback_reason == NO_GPU_DEVICE and made == []
    (tmp_path / "renderD128").touch()
    assert gpu_device_present()


def test_write_output_to_is_the_enhance_output_on_the_gpu() -> None:
    """GpuEnhancer.write_output_to leaves in the texture exactly what enhance() returns (the
    same OUTPUT buffer, copied GPU to GPU), and refuses a texture of the wrong shape."""
    moderngl = pytest.importorskip("moderngl")
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=450)
    except Exception as exc:
        pytest.skip(f"no OpenGL 4.5 through EGL: {exc}")
    try:
        enh = make_enhancer(DISPLAY, backend="gpu", ctx=ctx)
        img = np.random.default_rng(0).uniform(0, 1, (90, 80, 3)).astype(np.float32)
        enh.set_image(img, viewport=(80, 0, 160, 90))
        p = make_params(method="ours", blur_rate=0.34, impulses=12)
        tex = ctx.texture((80, 90), 3, dtype="f4")
        used = enh.write_output_to(tex, params=p)
        got = np.frombuffer(tex.read(), np.float32).reshape(90, 80, 3)
        assert used.s_k == pytest.approx(p.resolved().s_k)
        assert np.array_equal(got, enh.enhance(params=p).output)
        with pytest.raises(FovexpError, match="80x90, 3 components, f4"):
            enh.write_output_to(ctx.texture((80, 90), 4, dtype="f4"), params=p)
        enh.close()
    finally:
        ctx.release()
