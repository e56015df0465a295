"""Skipping on the GPU backend (EngineOptions.skip: work groups over a flat region or with no
live impulse exit early) is exact, as on the CPU: the output with it is the output without it,
bit for bit, and within the CPU parity tolerances of tests/gpu/test_backend.py."""

import numpy as np
import pytest

from fovexp import EngineOptions, EnhanceParams, Enhancer, FovexpError, load_display

from engine_helpers import mixed_scene

LG = load_display("lg-oled55cx")


@pytest.mark.parametrize("set_kw,gaze", [({}, (0.5, 0.5)), ({"foveated": True}, (0.35, 0.6))])
def test_gpu_skipping_changes_nothing_bit_for_bit(ctx, set_kw, gaze):
    from fovexp.gpu import GpuEnhancer

    image = mixed_scene(270, 480)
    p = EnhanceParams(blur_rate=0.57, impulses=24, seed=2)
    res = {}
    for skip in (True, False):
        enh = GpuEnhancer(LG, ctx=ctx, options=EngineOptions(skip=skip))
        enh.set_image(image, **set_kw)
        r = enh.enhance(gaze, p)
        res[skip] = {name: r.map(name) for name in ("output", "noise", "contrast", "foveated",
                                                    "amplitude")}
        with enh._current():  # every |L| level too (K reads only some of them)
            enh._c.get("abs_laplacian")
            res[skip]["abs_laplacian"] = enh._read("ABSLAP", enh._buffers["ABSLAP"].size // 4)
        enh.close()
    for name, on in res[True].items():
        assert np.array_equal(on.view(np.uint32), res[False][name].view(np.uint32)), name
    noise = res[True]["noise"]
    assert np.abs(noise).max() > 0.01 and (noise == 0).mean() > 0.2  # both kinds of group
    cpu = Enhancer(LG)
    cpu.set_image(image, **set_kw)
    ref = cpu.enhance(gaze, p)
    d = np.abs(ref.output - res[True]["output"])
    assert d.max() < 2e-3 and np.sqrt((d**2).mean()) < 2e-5


def test_the_gpu_refuses_the_options_it_does_not_implement(ctx):
    from fovexp.gpu import GpuEnhancer

    for kw, name in (({"dtype": "float64"}, "dtype"), ({"weights": "sign"}, "weights"),
                     ({"foveation": "exact"}, "foveation"), ({"cell_scale": 0.5}, "cell_scale")):
        with pytest.raises(FovexpError, match=f"engine option {name}="):
            GpuEnhancer(LG, ctx=ctx, options=EngineOptions(**kw))
    GpuEnhancer(LG, ctx=ctx, options=EngineOptions(skip=False)).close()
