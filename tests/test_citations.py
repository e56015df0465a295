"""Citations of the paper match the paper: section and equation numbers as its LaTeX numbers
them, and docs/METHOD.md's index (equation -> function -> shader) true of the code.

The paper's .tex is read from ``../shared/paper`` beside the repository (or
``$FOVEXP_PAPER_DIR``); the checks that need it skip with a reason when it is absent. The
checks of METHOD.md against the code run always.
"""

from __future__ import annotations

import importlib
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
METHOD = ROOT / "docs" / "METHOD.md"
SHADERS = ROOT / "fovexp" / "gpu" / "shaders"
PAPER_DIR = Path(os.environ.get("FOVEXP_PAPER_DIR", ROOT.parent / "shared" / "paper"))

#: A symbol each numbered equation's LaTeX must contain: if the paper's numbering and ours
#: drift apart (an equation added, or one counted twice), this fails.
EQUATION_SIGNATURES = {
    1: "F_L", 2: "F_H", 3: r"\mu_n", 4: r"\sigma_n", 5: r"\chi", 6: "f^l", 7: "f_{c}",
    8: "l_a", 9: "K(", 10: "SR(", 11: r"\hat{SR}",
}

#: Topics and the one paper section that covers them: a line of the project that cites a paper
#: section next to one of these words must cite this one.
TOPIC_SECTIONS = {
    "Table 2": "5.3",
    "1.25 deg": "5.1",
    "sampling-rate": "6.3",
    "t-test": "6.1",
    "Experiment Procedure": "5.2",
    "inter-frame SSIM": "6.2",
}

#: Files whose paper citations are checked: the package, shipped protocols, docs, benchmarks.
CITING_GLOBS = ("fovexp/**/*.py", "fovexp/gpu/shaders/*.glsl", "protocols/**/*.yaml",
                "docs/*.md", "benchmarks/*.py", "benchmarks/*.md", "README.md",
                "stimuli/README.md", "analysis/README.md")


# --- the paper -------------------------------------------------------------------------------

def _paper_tex() -> str:
    files = sorted(PAPER_DIR.glob("*.tex")) if PAPER_DIR.is_dir() else []
    if not files:
        pytest.skip(f"the paper's LaTeX is not at {PAPER_DIR} (set FOVEXP_PAPER_DIR)")
    return "\n".join(f.read_text(encoding="utf-8") for f in files)


def _strip_comments(tex: str) -> str:
    return re.sub(r"(?<!\\)%.*", "", tex)


def paper_sections(tex: str) -> dict[str, str]:
    """``{"4.2": "Amplitude", "A": "Detection and ...", ...}`` in the paper's numbering."""
    out: dict[str, str] = {}
    sec, sub, appendix = 0, 0, False
    cmd = re.compile(r"\\(appendix)\b|\\(my)?(sub)?section\*?\{([^}]*)\}")
    for line in _strip_comments(tex).splitlines():
        if line.lstrip().startswith("\\def"):
            continue  # the macros' definitions
        for m in cmd.finditer(line):
            if m.group(1):
                appendix, sec = True, 0
                continue
            title = m.group(4).strip()
            if m.group(3):
                sub += 1
                out[f"{_sec_name(sec, appendix)}.{sub}"] = title
            else:
                sec, sub = sec + 1, 0
                out[_sec_name(sec, appendix)] = title
    return out


def _sec_name(n: int, appendix: bool) -> str:
    return chr(ord("A") + n - 1) if appendix else str(n)


def paper_equations(tex: str) -> list[str]:
    """The LaTeX of each numbered equation, in order (``equation``, not ``equation*``)."""
    return re.findall(r"\\begin\{equation\}(.*?)\\end\{equation\}", _strip_comments(tex),
                      flags=re.S)


# --- docs/METHOD.md --------------------------------------------------------------------------

def _table_rows(heading: str) -> list[list[str]]:
    text = METHOD.read_text(encoding="utf-8")
    part = text.split(heading, 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in part.splitlines():
        if line.startswith("|") and not line.startswith("|---"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]
            rows.append(cells)
    return rows[1:]  # without the header


def method_sections() -> dict[str, str]:
    return {r[0]: r[1] for r in _table_rows("## 1. Paper sections")}


def method_equations() -> list[tuple[int, list[str], dict[str, list[str]]]]:
    """``(N, python qualified names, {shader file: names})`` per row of METHOD.md section 2."""
    out = []
    for cells in _table_rows("## 2. Equations"):
        n = int(cells[0])
        python = re.findall(r"`(fovexp\.[\w.]+)`", cells[2])
        glsl: dict[str, list[str]] = {}
        for m in re.finditer(r"`(\w+\.glsl)`:\s*((?:`\w+`(?:,\s*)?)+)", cells[3]):
            glsl[m.group(1)] = re.findall(r"`(\w+)`", m.group(2))
        out.append((n, python, glsl))
    return out


def _resolve(qualified: str) -> object:
    module, _, name = qualified.rpartition(".")
    return getattr(importlib.import_module(module), name)


def cited_equations(doc: str) -> set[int]:
    """Equation numbers a docstring cites: ``eq. 7``, ``eqs. 3-4``, ``eqs. 10-11``."""
    out: set[int] = set()
    for m in re.finditer(r"\beqs?\. (\d+)(?:\s*-\s*(\d+))?", doc):
        lo = int(m.group(1))
        out.update(range(lo, int(m.group(2) or lo) + 1))
    return out


# --- tests -----------------------------------------------------------------------------------

def test_equation_table_covers_every_equation_once_in_order():
    numbers = [n for n, _, _ in method_equations()]
    assert numbers == list(range(1, len(numbers) + 1))
    assert len(numbers) == len(EQUATION_SIGNATURES)


def test_each_mapped_function_exists_and_cites_its_equation():
    for n, python, _ in method_equations():
        assert python or n >= 10 or pytest.fail(f"eq. {n} maps to no function")
        for name in python:
            doc = _resolve(name).__doc__ or ""
            assert n in cited_equations(doc), f"{name}'s docstring does not cite eq. {n}"


def test_each_mapped_shader_function_is_defined_in_its_file():
    for n, _, glsl in method_equations():
        for file, names in glsl.items():
            src = (SHADERS / file).read_text(encoding="utf-8")
            for name in names:
                defined = re.search(rf"\b(?:float|vec[234]|int|bool|void)\s+{name}\s*\(", src)
                entry = f"ENTRY_{name}" in src
                assert defined or entry, f"eq. {n}: {name} is not defined in {file}"


def test_paper_numbered_equations_are_the_indexed_ones():
    eqs = paper_equations(_paper_tex())
    assert len(eqs) == len(EQUATION_SIGNATURES), f"the paper numbers {len(eqs)} equations"
    for n, sign in EQUATION_SIGNATURES.items():
        assert sign in eqs[n - 1], f"paper eq. {n} is not the one with {sign}: {eqs[n - 1]!r}"


def test_method_section_table_matches_the_paper():
    paper = paper_sections(_paper_tex())
    ours = method_sections()
    assert set(ours) == set(paper), (set(ours) ^ set(paper))
    for number, title in ours.items():
        assert title.lower() == paper[number].lower(), (number, title, paper[number])


def _citing_lines() -> list[tuple[str, int, str]]:
    lines = []
    for pattern in CITING_GLOBS:
        for path in sorted(ROOT.glob(pattern)):
            rel = str(path.relative_to(ROOT))
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                lines.append((rel, i, line))
    return lines


PAPER_SECTION = re.compile(
    r"paper(?:'s)? (?:appendix |sections? )((?:[\dA](?:\.\d)?)(?:(?:, | and )[\dA](?:\.\d)?)*)")


def test_every_cited_paper_section_and_equation_exists():
    tex = _paper_tex()
    sections, n_eq = paper_sections(tex), len(paper_equations(tex))
    bad = []
    for rel, i, line in _citing_lines():
        for m in PAPER_SECTION.finditer(line):
            for number in re.split(r", | and ", m.group(1)):
                if number not in sections:
                    bad.append(f"{rel}:{i}: paper section {number}")
        if rel.startswith("fovexp/"):
            bad += [f"{rel}:{i}: eq. {n}" for n in cited_equations(line) if n > n_eq]
    assert not bad, "citations of what the paper does not have:\n" + "\n".join(bad)


def test_topics_cite_the_section_that_covers_them():
    bad = []
    for rel, i, line in _citing_lines():
        if re.search(r"issue \d+", line):
            continue
        for topic, section in TOPIC_SECTIONS.items():
            at = line.find(topic)
            # the first section cited after the topic on its line (none: nothing to check)
            cited = re.search(r"\b[Ss]ections? (\d\.\d)\b", line[at:]) if at >= 0 else None
            if cited and cited.group(1) != section:
                bad.append(f"{rel}:{i}: {topic!r} cites {cited.group(1)}, not {section}")
    assert not bad, "\n".join(bad)


def test_module_docs_cite_method_md_not_the_notes():
    """The package cites docs/METHOD.md, which ships with it, not a file outside the repo."""
    bad = [f"{rel}:{i}" for rel, i, line in _citing_lines()
           if rel.startswith("fovexp/") and re.search(r"ALGORITHM-NOTES|\bnotes (section )?\d",
                                                        line)]
    assert not bad, bad
    for rel, i, line in _citing_lines():
        for m in re.finditer(r"docs/METHOD\.md, (\d+(?:\.\d+)?)", line):
            assert _method_has(m.group(1)), f"{rel}:{i}: METHOD.md has no {m.group(1)}"


def _method_has(number: str) -> bool:
    text = METHOD.read_text(encoding="utf-8")
    if "." in number:
        return re.search(rf"^{re.escape(number)} \*\*", text, flags=re.M) is not None
    return re.search(rf"^## {number}\. ", text, flags=re.M) is not None


#: The stage modules (one per stage of the paper) and the DOIs their References must give.
STAGE_REFERENCES = {
    "geometry": [], "acuity": [], "foveation": ["10.1145/2980179.2980246"],
    "contrast": ["10.1145/2980179.2980246"], "pyramids": ["10.1109/TCOM.1983.1095851"],
    "frequency": [], "amplitude": [], "orientation": ["10.1109/TASSP.1981.1163711"],
    "gabor": ["10.1145/1531326.1531360"], "colour": [], "sequence": ["10.1109/TIP.2003.819861"],
}
TARIQ_DOI = "10.1145/3528223.3530101"


@pytest.mark.parametrize("module", sorted(STAGE_REFERENCES))
def test_stage_modules_end_with_references(module):
    doc = importlib.import_module(f"fovexp.{module}").__doc__ or ""
    assert "\nReferences\n----------\n" in doc, module
    refs = doc.split("\nReferences\n", 1)[1]
    for doi in [TARIQ_DOI, *STAGE_REFERENCES[module]]:
        assert f"doi:{doi}" in refs, (module, doi)
