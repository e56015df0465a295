"""The analysis on partial data and its figures' layout (issue 18, section 6): ``fovexp
analyze`` reports what it can when a scene lacks one of the methods and says what is missing;
no text of any figure the analysis makes leaves the canvas or overlaps another
(:func:`fovexp.analysis.figures.text_problems`, itself shown to catch both)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from fovexp.analysis import figures
from fovexp.analysis.report import run_analysis
from fovexp.analysis.validation import missing_cells, validate
from fovexp.results import load_results
from fovexp.results.format import FRAME_COLUMNS, format_value

from analysis_fixtures import write_study


def test_the_checker_catches_overlap_and_a_text_off_the_canvas() -> None:
    fig = Figure(figsize=(4, 3), layout="constrained")
    ax = fig.subplots()
    ax.set_title("a title")
    assert figures.text_problems(fig) == []
    fig.text(0.5, 0.5, "overlapping", ha="center")
    fig.text(0.5, 0.51, "each other", ha="center")
    got = figures.text_problems(fig)
    assert any("overlaps" in g for g in got), got
    fig2 = Figure(figsize=(4, 3), layout="constrained")
    fig2.subplots().set_title("a title far too long for a figure four inches wide, it runs off "
                              "both sides of it")
    assert any("leaves the canvas" in g for g in figures.text_problems(fig2))
    # the old captions: below the canvas, over the tick labels
    fig3 = Figure(figsize=(4, 3))
    ax3 = fig3.subplots()
    ax3.set_xticks([0, 1])
    ax3.set_xticklabels(["first label", "second"], rotation=90)
    fig3.text(0.5, -0.02, "a caption under the panels", ha="center", va="top")
    assert any("leaves the canvas" in g for g in figures.text_problems(fig3))


def frame_log(folder: Path, session: str, rng: np.random.Generator) -> None:
    rows = []
    t = 10_000_000
    for k in range(40):
        t += 8333
        lat = int(rng.uniform(3_000, 25_000))
        rows.append([0, 0, k, t / 1e6, 0.008333 if k else None, 0, 0, 0.2, t - lat, 0.3, t,
                     t - 1000])
    with open(folder / f"frames-{session}.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(FRAME_COLUMNS)
        w.writerows([[format_value(v) for v in r] for r in rows])


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every experiment, 12 participants (48 sessions, each with a frame log), one validation
    scene without `ours` for one participant and another without `ours` for anyone."""
    root = write_study(tmp_path_factory.mktemp("results"), n_participants=12, seed=5)
    rng = np.random.default_rng(1)
    for path in root.rglob("trials.csv"):
        rows = list(csv.DictReader(path.open()))
        if "validation" in path.parts:
            rows = [r for r in rows if not (r["method"] == "ours" and (
                r["image"] == "scene03" or (r["image"] == "scene05"
                                            and r["participant"] == "P02")))]
            with open(path, "w", newline="") as fh:
                w = csv.DictWriter(fh, list(rows[0]), lineterminator="\n")
                w.writeheader()
                w.writerows(rows)
        frame_log(path.parent, rows[0]["session"], rng)
        info = path.parent / f"session-{rows[0]['session']}.json"
        data = json.loads(info.read_text())
        info.write_text(json.dumps({**data, "display_check": {"refresh_hz": 120.0}}))
    return root


def test_validation_on_partial_data_reports_what_it_can(study: Path) -> None:
    trials = load_results(study).experiment("validation")
    gaps = missing_cells(trials)
    assert {(g["image"], g["participant"]) for _, g in gaps.iterrows()} == {
        ("scene03", ""), ("scene05", "P02")}
    res = validate(trials)
    assert "scene03" not in set(res.tests["scope"]) and "scene05" in set(res.tests["scope"])
    assert int(res.tests.set_index("scope").loc["scene05", "n"]) == 11
    assert "scene03" not in set(res.sampling["scope"])
    assert any("scene scene03 has no trials of ours" in n for n in res.notes)
    assert any("P02 x scene05 lacks ours" in n for n in res.notes)
    # nothing compared at all: the means still, and a note instead of an error
    only = trials[~((trials["method"] == "ours") & (trials["participant"] == "P01"))
                  & ~((trials["method"] == "contrast") & (trials["participant"] != "P01"))]
    res = validate(only)
    assert res.tests.empty and res.sampling.empty and len(res.summary)
    assert any("no participant x scene has both ours and contrast" in n for n in res.notes)


def test_no_text_of_any_figure_overlaps_or_leaves_the_canvas(study: Path, tmp_path: Path,
                                                              monkeypatch) -> None:
    made: dict[str, Figure] = {}
    save = figures._save

    def keep(fig: Figure, stem: Path) -> list[Path]:
        made[stem.name] = fig
        return save(fig, stem)

    monkeypatch.setattr(figures, "_save", keep)
    ana = run_analysis(study, tmp_path / "report")
    assert set(made) == {"calibration", "validation", "validation-sampling", "latency"}
    for name, fig in made.items():
        assert figures.text_problems(fig) == [], name
    report = ana.report.read_text()
    assert "## Validation: validation" in report and "scene scene03 has no trials of ours" in report
    # the PNG is the canvas the check saw (saved as laid out, not grown around a text)
    from PIL import Image

    with Image.open(tmp_path / "report" / "figures" / "latency.png") as im:
        w, h = made["latency"].get_size_inches() * 150
        assert im.size == (round(w), round(h))
