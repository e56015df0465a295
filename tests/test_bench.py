"""``fovexp bench`` (fovexp/bench.py): its statistics on synthetic data with known answers, the
Pareto front, the knob selection, and a tiny real run that writes every file."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from fovexp import FovexpError
from fovexp.bench import (
    RINGS_DEG,
    band_power_fraction,
    columns,
    configs_for,
    excess_kurtosis,
    noise_statistics,
    pareto_front,
    ring_label,
    rmse_8bit,
)
from fovexp.cli import main


def test_excess_kurtosis_of_known_distributions():
    rng = np.random.default_rng(0)
    assert abs(excess_kurtosis(rng.standard_normal(1_000_000))) < 0.02
    assert excess_kurtosis(np.array([-1.0, 1.0] * 1000)) == pytest.approx(-2.0)
    assert excess_kurtosis(rng.laplace(size=1_000_000)) == pytest.approx(3.0, abs=0.1)
    assert math.isnan(excess_kurtosis(np.ones(10)))


@pytest.mark.parametrize("angle", [0.0, 0.7, 1.9])
def test_band_power_of_a_sinusoid(angle):
    """All of a 0.1 cycles/px grating's power is inside a band around 0.1, none in another."""
    n = 64
    yy, xx = np.mgrid[0:n, 0:n]
    f = 0.1
    tile = np.cos(2 * np.pi * f * (xx * np.cos(angle) + yy * np.sin(angle)) + 0.3)
    inside, total = band_power_fraction(tile, 0.07, 0.13)
    assert inside[0] / total[0] > 0.95
    inside, total = band_power_fraction(tile, 0.2, 0.45)
    assert inside[0] / total[0] < 0.01
    # a closed band (F_L = inf: the band is empty) holds nothing
    inside, _ = band_power_fraction(tile, np.inf, 0.5)
    assert inside[0] == 0.0


def _field(shape, k, band_cpp, rng, sparse=False):
    """Noise of std k/6 whose power lies in an annulus of the spectrum (band_cpp), Gaussian, or
    sparse (a few band-passed spikes, heavy-tailed)."""
    h, w = shape
    if sparse:
        white = np.zeros(shape)
        idx = rng.integers(0, h * w, size=h * w // 2000)
        white.flat[idx] = rng.choice([-1.0, 1.0], size=idx.size)
    else:
        white = rng.standard_normal(shape)
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.fftfreq(w)[None, :]
    fr = np.hypot(fy, fx)
    spec = np.fft.fft2(white) * ((fr >= band_cpp[0]) & (fr <= band_cpp[1]))
    noise = np.real(np.fft.ifft2(spec))
    return noise / noise.std() * k / 6


def test_noise_statistics_recover_a_known_field():
    rng = np.random.default_rng(1)
    h, w = 512, 1024
    k = np.full((h, w), 0.3)
    band = (0.1, 0.25)
    noise = _field((h, w), 0.3, band, rng)
    ecc = np.broadcast_to(np.linspace(0, 50, w), (h, w))  # rings across the width
    lo, hi = np.full((h, w), band[0]), np.full((h, w), band[1])
    st = noise_statistics(noise, k, lo, hi, ecc)
    allr = st["all"]
    assert allr["std_over_k"] == pytest.approx(1 / 6, rel=0.03)
    assert abs(allr["excess_kurtosis"]) < 0.1
    assert allr["band_frac"] > 0.8  # the window leaks a little past the band's edges
    for ring in RINGS_DEG:
        assert st[ring_label(ring)]["tiles"] > 0
    # the fovea (0-8 deg) is in no ring
    assert sum(st[ring_label(r)]["tiles"] for r in RINGS_DEG) < allr["tiles"]
    # the statistics respond: twice the noise, twice std/K; a band elsewhere, little power in
    # the stated band; sparse noise, a heavy tail
    assert noise_statistics(2 * noise, k, lo, hi, ecc)["all"]["std_over_k"] == pytest.approx(
        2 * allr["std_over_k"])
    assert noise_statistics(noise, k, lo + 0.2, hi + 0.2, ecc)["all"]["band_frac"] < 0.1
    sparse = _field((h, w), 0.3, band, rng, sparse=True)
    assert noise_statistics(sparse, k, lo, hi, ecc)["all"]["excess_kurtosis"] > 1.0
    # no noise anywhere: no tile counts, every figure NaN rather than a made-up number
    empty = noise_statistics(noise, np.zeros((h, w)), lo, hi, ecc)
    assert empty["all"]["tiles"] == 0 and math.isnan(empty["all"]["band_frac"])


def test_rmse_in_8bit_codes():
    a = np.zeros((4, 4, 3), np.float32)
    assert rmse_8bit(a, a + 1 / 255) == pytest.approx(1.0)


def test_pareto_front():
    times = [1.0, 2.0, 3.0, 0.5, 4.0, float("nan")]
    errors = [0.5, 0.6, 0.1, 0.9, 0.1, 0.0]
    # (0.5, 0.9) fastest; (1, 0.5) better; (2, 0.6) beaten by (1, 0.5); (3, 0.1); (4, 0.1) ties
    # (3, 0.1) in error at a higher time: beaten; the NaN time is left out
    assert pareto_front(times, errors) == [3, 0, 2]


def test_knob_selection():
    cfgs = configs_for(["dtype", "impulses=256"], 64, "cpu", (480, 270), ((240, 135),))
    assert [c.name for c in cfgs] == ["impulses=64", "dtype=float64", "impulses=256"]
    assert cfgs[1].options_dict == {"dtype": "float64"} and cfgs[1].same_field
    noise = configs_for(["noise"], 64, "cpu", (480, 270), ())
    assert not any(c.same_field for c in noise[1:])
    # the options the GPU backend does not implement stay on the CPU
    gpu = configs_for(["impulses=12", "foveation"], 64, "gpu", (480, 270), ())
    assert [(c.name, c.backend) for c in gpu] == [
        ("impulses=64", "gpu"), ("impulses=12", "gpu"), ("foveation=exact", "cpu")]
    with pytest.raises(FovexpError, match="unknown knob 'speed'"):
        configs_for(["speed"], 64, "cpu", (480, 270), ())


def test_bad_arguments_are_one_line(capsys, tmp_path):
    assert main(["bench", "--knobs", "speed", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fovexp: error: unknown knob 'speed'") and "\n" not in err
    with pytest.raises(SystemExit):
        main(["bench", "--resolution", "4k"])
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["bench", "--image", str(tmp_path / "none.png"), "--out", str(tmp_path / "b")]) == 2
    assert "none.png: no such image" in capsys.readouterr().err
    assert not (tmp_path / "b").exists()  # nothing written before the arguments are checked


@pytest.mark.slow
def test_a_tiny_run_writes_every_file(tmp_path, capsys):
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "--knobs",
                 "impulses=12,dtype=float64", "--repeats", "1", "--out", str(out),
                 "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "impulses=12" in printed and "RMSE paired" in printed
    with open(out / "bench.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0].keys()) == columns()
    assert [r["config"] for r in rows] == ["reference", "impulses=64", "impulses=12",
                                           "dtype=float64"]
    by = {r["config"]: r for r in rows}
    assert float(by["reference"]["rmse_ref_8bit"]) == 0.0
    for name in ("impulses=64", "impulses=12", "dtype=float64"):
        r = by[name]
        assert not r["skipped"]
        assert float(r["median_s"]) > 0 and float(r["peak_rss_mb"]) > float(r["base_rss_mb"]) > 0
        assert 0 < float(r["rmse_paired_8bit"]) < float(r["rmse_ref_8bit"])
        assert r["device"].startswith("CPU")
    md = (out / "BENCH.md").read_text()
    assert "Machine:" in md and "Reference: 256 impulses" in md and "RMSE paired" in md
    for png in ("bench_pareto_rmse.png", "bench_pareto_noise.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "bench.json").is_file()


def test_the_cpu_roofline_puts_each_stage_against_its_floor() -> None:
    """Issue 29: a stage's floor is its least traffic at the measured bandwidth; the noise's
    the larger of that and its taps' arithmetic; stages without a per-pixel model are left
    out. Values hand-computed: a 100 x 50 frame, one float32 plane = 20 000 bytes."""
    from fovexp.bench import machine_rates, roofline_rows

    row = {"resolution": "100x50", "stages_s": "contrast=0.0020;noise=0.0100;imp_band=0.1000",
           "noise_taps": 1e6}
    rates = {"bandwidth_gb_s": 10.0, "fp32_gflop_s": 100.0}
    got = {r[0]: r for r in roofline_rows(row, rates)}
    assert sorted(got) == ["contrast", "noise"]
    # contrast: 1 plane in, 1 out: 40 kB at 10 GB/s = 4 us; 2 ms is 500 times that
    assert got["contrast"][2:] == ["2.0", "0", "", "0.0", "500.0x"]
    # noise: 1 plane out (2 us) or 4e6 FLOP at 100 GFLOP/s (40 us): the arithmetic bounds it
    assert got["noise"][4:] == ["0.00 GFLOP", "0.0", "250.0x"]
    small = machine_rates(copy_mb=8, gemm_n=64, repeats=2)
    assert small["bandwidth_gb_s"] > 0.1 and small["fp32_gflop_s"] > 0.01
    # every thread against one on the same work: a ratio of two timings, at most one per
    # thread; a busy host's second thread can make it fall below 1 (0.93 measured in
    # CPU_FLOOR.md's run), never to 0 or infinity
    assert 0.25 < small["parallel_speedup"] < small["threads"] + 0.5


def test_the_records_say_what_the_threads_gained() -> None:
    """The roofline's sentence on the threads' speedup, and none for a record from before
    it was measured."""
    from fovexp.bench import parallel_sentence

    assert parallel_sentence({"parallel_speedup": 1.274, "threads": 2}) == (
        " Its 2 threads together ran arithmetic-bound compiled work 1.27x as fast as one did "
        "(fovexp._parallel.parallel_speedup): the most the parallel kernels can gain from "
        "them.")
    assert parallel_sentence({"bandwidth_gb_s": 20.0}) == ""
