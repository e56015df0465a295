"""Parameters at every edge of their ranges (PARAMETER_RANGES, impulses 1..512, seed
0..2**31 - 1, the engine options' bounds) keep every invariant; NaN, Inf and values outside
are refused in one line naming the parameter and its range, through the API
(``make_params``, ``make_options``) and ``fovexp enhance`` (exit status 2)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fovexp import (
    PARAMETER_RANGES,
    EngineOptions,
    Enhancer,
    FovexpError,
    make_options,
    make_params,
    write_image,
)
from fovexp.amplitude import CLIPPING_RULES

from stress.checks import check_result
from stress.strategies import examples, gazes, image_cases, noisy_setups, param_kwargs, viewports
from stress.test_images import LG, run_cli


@given(setup=noisy_setups(), data=st.data())
def test_parameters_at_their_edges_keep_every_invariant(setup, data):
    """Every number at or next to an edge of its range (or anywhere inside), every method and
    preset, on frames where the noise has room to appear."""
    case, _, vp, gaze = setup
    kw = data.draw(param_kwargs())
    img = case.image()
    enh = Enhancer(LG, preset=kw["preset"])
    enh.set_image(img, viewport=vp)
    check_result(enh, enh.enhance(gaze, make_params(**kw)), img)


option_kwargs = st.fixed_dictionaries({
    "skip": st.booleans(),
    "dtype": st.sampled_from(["float32", "float64"]),
    "kernel_truncation": st.sampled_from([1e-6, 0.01, 0.5]) | st.floats(1e-6, 0.5),
    "impulse_count": st.sampled_from(["poisson", "jittered"]),
    "weights": st.sampled_from(["uniform", "sign"]),
    "cell_scale": st.sampled_from([0.25, 1.0]) | st.floats(0.25, 1.0),
    "clipping": st.sampled_from([None, *CLIPPING_RULES]),
})


@settings(max_examples=examples(0.5))
@given(setup=noisy_setups(presets=("paper",)), opts=option_kwargs)
def test_engine_options_at_their_edges_keep_every_invariant(setup, opts):
    case, kw, vp, gaze = setup
    img = case.image()
    enh = Enhancer(LG, options=make_options(**opts))
    enh.set_image(img, viewport=vp)
    check_result(enh, enh.enhance(gaze, make_params(**kw)), img)


#: (name, CLI option, unit text of the range), as fovexp.params.check_parameter words it
NUMBERS = {
    "blur_rate": ("--blur-rate", "[0, 5] arcmin/deg"),
    "f_e": ("--fe", "[0, 2]"),
    "s_k": ("--sk", "[0, 200]"),
    "s_f": ("--sf", "(0, 50]"),
    "impulses": ("--impulses", "[1, 512] per kernel"),
    "seed": ("--seed", "[0, 2147483647]"),
}
INTEGERS = {"impulses": (1, 512), "seed": (0, 2**31 - 1)}


@st.composite
def bad_values(draw):
    """(parameter, a value it must refuse): NaN, +-Inf, just outside the range, far outside,
    and, for the integers, a fraction."""
    name = draw(st.sampled_from(sorted(NUMBERS)))
    if name in INTEGERS:
        lo, hi = INTEGERS[name]
        value = draw(st.sampled_from([lo - 1, hi + 1, 0.5 + lo, math.nan, math.inf])
                     | st.integers(max_value=lo - 1) | st.integers(min_value=hi + 1))
    else:
        lo, hi = PARAMETER_RANGES[name]
        outside = [math.nan, math.inf, -math.inf, math.nextafter(hi, math.inf), hi * 10,
                   math.nextafter(lo, -math.inf), -1e300]
        if name == "s_f":
            outside.append(0.0)  # open at 0: the log-normal needs a width
        value = draw(st.sampled_from(outside)
                     | st.floats(max_value=lo, exclude_max=True, allow_infinity=True)
                     | st.floats(min_value=hi, exclude_min=True, allow_infinity=True))
    return name, value


@given(bad=bad_values())
def test_the_api_refuses_bad_parameters_in_one_line(bad):
    name, value = bad
    with pytest.raises(FovexpError) as exc:
        make_params(**{name: value})
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"parameter: {name}=")
    assert NUMBERS[name][1] in msg, msg


@settings(max_examples=examples(0.5))
@given(bad=bad_values())
def test_the_cli_refuses_bad_parameters_in_one_line_with_status_2(tmp_path_factory, bad):
    import numpy as np

    name, value = bad
    option, accepted = NUMBERS[name]
    folder = tmp_path_factory.mktemp("bad")
    src, out = folder / "in.png", folder / "out.png"
    write_image(src, np.full((16, 16), 0.5, np.float32))
    text = repr(value) if isinstance(value, float) and math.isfinite(value) else str(value)
    rc, err = run_cli("enhance", src, out, f"{option}={text}")
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith(f"fovexp: error: argument {option}: ") and accepted in lines[0]
    assert not out.exists()


@given(name=st.sampled_from(["kernel_truncation", "cell_scale"]),
       value=st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 2.0, 1e-7, 0.2, -1.0]))
def test_the_api_refuses_bad_engine_options_in_one_line(name, value):
    lo, hi = {"kernel_truncation": (1e-6, 0.5), "cell_scale": (0.25, 1.0)}[name]
    if lo <= value <= hi:
        EngineOptions(**{name: value})  # inside: accepted
        return
    with pytest.raises(FovexpError) as exc:
        make_options(**{name: value})
    assert "\n" not in str(exc.value) and name in str(exc.value)


@settings(max_examples=examples(0.5))
@given(case=image_cases(kinds=("texture",)), gaze=gazes, data=st.data())
def test_the_table_fills_what_is_left_out_with_the_edges_of_blur_rate(case, gaze, data):
    """f_e, s_k, s_f from the table at blur-rates outside its rows (clamped): still a valid
    frame at blur-rate 0 and 5."""
    img = case.image()
    vp = data.draw(viewports(case.height, case.width))
    blur = data.draw(st.sampled_from(list(PARAMETER_RANGES["blur_rate"])))
    preset = data.draw(st.sampled_from(["paper", "release"]))
    enh = Enhancer(LG, preset=preset)
    enh.set_image(img, viewport=vp)
    res = enh.enhance(gaze, make_params(blur_rate=blur, preset=preset, impulses=12))
    for name in ("f_e", "s_k", "s_f"):
        lo, hi = PARAMETER_RANGES[name]
        assert lo <= getattr(res.params, name) <= hi
    check_result(enh, res, img)
