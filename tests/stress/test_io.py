"""16-bit in, 16-bit out through ``fovexp enhance``, as a property over random 16-bit images
of every layout (grey, grey + alpha, RGB, RGBA): the output keeps the depth, the layout and
the alpha channel sample for sample, and holds what the API computes, quantised."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fovexp import Enhancer, make_params, read_image
from fovexp.io import read_samples

from stress.checks import quantise
from stress.strategies import examples, gazes, image_cases, param_kwargs
from stress.test_images import LG, run_cli


@settings(max_examples=examples(0.5))
@given(case=image_cases(depths=(16,)), kw=param_kwargs(presets=("paper",)), gaze=gazes,
       suffix=st.sampled_from([".png", ".tif"]))
def test_sixteen_bit_in_sixteen_bit_out_through_the_cli(tmp_path_factory, case, kw, gaze, suffix):
    from fovexp import write_image

    img = case.image()
    folder = tmp_path_factory.mktemp("io16")
    src, out = folder / f"in{suffix}", folder / f"out{suffix}"
    write_image(src, img, 16)
    samples_in = read_samples(src)
    assert samples_in.dtype == np.uint16
    args = ["--gaze", f"{gaze[0]!r},{gaze[1]!r}", "--method", kw["method"],
            "--blur-rate", repr(kw["blur_rate"]), "--impulses", kw["impulses"],
            "--seed", kw["seed"]]
    for name, option in (("f_e", "--fe"), ("s_k", "--sk"), ("s_f", "--sf")):
        if name in kw:
            args += [option, repr(kw[name])]
    rc, err = run_cli("enhance", src, out, *args, "--display", "lg-oled55cx")
    assert rc == 0, err
    got = read_samples(out)
    assert got.dtype == np.uint16 and got.shape == samples_in.shape
    if case.channels in (2, 4):
        assert np.array_equal(got[..., -1], samples_in[..., -1])
    enh = Enhancer(LG)
    enh.set_image(read_image(src))
    res = enh.enhance(gaze, make_params(**kw))
    assert np.array_equal(got.astype(np.int64), quantise(res.output, 16))
