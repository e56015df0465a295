"""The package's layers point one way (docs/API.md): an import graph of ``fovexp`` read with the
standard library's :mod:`ast` (every ``import`` statement, also those inside functions), then
checked for cycles and for the rules between its parts."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

try:
    import tomllib
except ImportError:  # Python 3.10: pytest's own dependency
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "fovexp"


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def imports_of(name: str, path: Path, known: set[str]) -> set[str]:
    """The ``fovexp`` modules ``name`` imports. ``from a import b`` counts as importing
    ``a.b`` when that is a module, else ``a``; importing ``a.b`` also runs ``a/__init__``, but
    that edge is the import system's, not the code's, and is left out (it would make every
    subpackage "import" its parent)."""
    is_pkg = path.name == "__init__.py"
    package = name if is_pkg else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                       for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in known:  # ``import fovexp.gpu.backend as b`` etc.
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports_of(name, path, known) for name, path in mods.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_walker_sees_a_cycle():
    """The check itself: a two-module cycle and a self-contained chain."""
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_no_import_cycle(graph):
    assert cycles(graph) == []


def _edges(graph, src_prefix: str, dst_prefix: str) -> list[tuple[str, str]]:
    def under(m: str, p: str) -> bool:
        return m == p or m.startswith(p + ".")

    return sorted((a, b) for a, deps in graph.items() if under(a, src_prefix)
                  for b in deps if under(b, dst_prefix))


def test_the_pipeline_does_not_know_the_gpu_backend(graph):
    assert _edges(graph, "fovexp.pipeline", "fovexp.gpu") == []


def test_runner_and_analysis_do_not_import_each_other(graph):
    assert _edges(graph, "fovexp.experiment", "fovexp.analysis") == []
    assert _edges(graph, "fovexp.analysis", "fovexp.experiment") == []
    assert _edges(graph, "fovexp.results", "fovexp.experiment") == []
    assert _edges(graph, "fovexp.results", "fovexp.analysis") == []


def test_the_monitor_reads_files_only(graph):
    """``fovexp monitor`` shares nothing with a session but the files on disk: it imports
    neither the runner nor the analysis (nor, through them, PsychoPy or moderngl); the runner
    reaches it only from its command line (``fovexp run --monitor`` starts it as a process)."""
    assert _edges(graph, "fovexp.monitor", "fovexp.experiment") == []
    assert _edges(graph, "fovexp.monitor", "fovexp.analysis") == []
    assert _edges(graph, "fovexp.monitor", "fovexp.gpu") == []
    assert _edges(graph, "fovexp.experiment", "fovexp.monitor") in (
        [], [("fovexp.experiment.cli", "fovexp.monitor.cli")])
    assert _edges(graph, "fovexp.results", "fovexp.monitor") == []
    for path in (PACKAGE / "monitor").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("psychopy", "moderngl", "pyglet")
                           for n in names), path


def test_runner_does_not_import_the_cli(graph):
    assert _edges(graph, "fovexp.experiment", "fovexp.cli") == []


@pytest.mark.parametrize("part", ["fovexp.experiment", "fovexp.analysis", "fovexp.results",
                                  "fovexp.monitor"])
def test_runner_and_analysis_use_the_public_api(graph, part):
    """Of the enhancer they import only the package's public names (``from fovexp import``,
    docs/API.md), the shared logs layer ``fovexp.results``, and their own modules."""
    allowed = ("fovexp", "fovexp.results", part)
    if part == "fovexp.experiment":  # the stimuli are a layer of their own (below)
        allowed += ("fovexp.stimuli",)
    # ``fovexp run --monitor`` starts ``fovexp monitor`` beside the session
    beside = ("fovexp.experiment.cli", "fovexp.monitor.cli")
    bad = [(a, b) for a, b in _edges(graph, part, "fovexp")
           if not (b == "fovexp" or any(b == p or b.startswith(p + ".") for p in allowed[1:]))
           and (a, b) != beside]
    assert bad == []


def test_the_engine_does_not_import_the_runner_or_the_analysis(graph):
    engine = [m for m in graph if not m.startswith(("fovexp.experiment", "fovexp.analysis",
                                                    "fovexp.results", "fovexp.monitor",
                                                    "fovexp.cli", "fovexp.__main__", "fovexp.bench",
                                                    "fovexp.stimuli",
                                                    "fovexp.evaluation", "fovexp.rig",
                                                    "fovexp.export",
                                                    # compiles every kernel, the evaluation's too
                                                    "fovexp.warmup"))]
    bad = [(a, b) for a in engine for b in graph[a]
           if b.startswith(("fovexp.experiment", "fovexp.analysis", "fovexp.results",
                            "fovexp.evaluation"))]
    assert bad == []


def test_the_stimuli_sit_on_the_public_api(graph):
    """``fovexp.stimuli`` (the scenes, a lab's stimulus folder, ``fovexp stimuli``) is read by
    the runner, the rig check and the bench: it imports the enhancer's public names and its own
    modules, and only its command line's ``check`` reads a protocol."""
    bad = [(a, b) for a, b in _edges(graph, "fovexp.stimuli", "fovexp")
           if b != "fovexp" and not b.startswith("fovexp.stimuli.")
           and (a, b) != ("fovexp.stimuli.cli", "fovexp.experiment.protocol.spec")]
    assert bad == []


#: The runner's rooms, lowest first: each may import the rooms before it (and
#: ``fovexp.experiment.interfaces``), never one after it (docs/EXPERIMENT.md, "The runner's
#: rooms"; each room's ``__init__`` says the same).
ROOMS = ("protocol", "trackers", "tasks", "display", "records")
#: What lives at the top of ``fovexp.experiment``: the session's plan, its options, its command
#: line, the structural types the rooms share, the package itself.
TOP = {"__init__", "session", "options", "cli", "interfaces"}


def _room(module: str) -> str | None:
    parts = module.split(".")
    if parts[:2] != ["fovexp", "experiment"] or len(parts) < 3:
        return None
    return parts[2] if parts[2] in ROOMS else "top:" + parts[2]


def test_the_runner_has_its_rooms():
    """At most 8 modules at the runner's top level; every room a package whose docstring says
    what lives in it and what it may import."""
    top = {p.stem for p in (PACKAGE / "experiment").glob("*.py")}
    assert top == TOP and len(top) <= 8
    for room in ROOMS:
        doc = ast.get_docstring(ast.parse((PACKAGE / "experiment" / room / "__init__.py")
                                          .read_text()))
        assert doc and "May import" in doc, room
    assert len((PACKAGE / "experiment" / "session.py").read_text().splitlines()) <= 400


def test_the_rooms_import_downwards(graph):
    """A room imports only rooms below it (:data:`ROOMS`), the shared types
    (``interfaces``) and, outside the runner, the public API, the logs layer and the stimuli;
    no room imports ``session``, ``options`` or ``cli``; ``interfaces`` holds types only."""
    bad = []
    for a, deps in graph.items():
        ra = _room(a)
        if ra is None or ra.startswith("top:") and ra != "top:interfaces":
            continue
        for b in deps:
            rb = _room(b)
            if rb is None or rb == ra:
                continue
            if ra == "top:interfaces":
                ok = b in ("fovexp.experiment.trackers.gaze", "fovexp.experiment.tasks.trial",
                           "fovexp.experiment.display.render")
            elif rb == "top:interfaces":
                ok = True
            else:
                ok = rb in ROOMS and ROOMS.index(rb) < ROOMS.index(ra)
            if not ok:
                bad.append((a, b))
    assert bad == []
    users = sorted(a for a, deps in graph.items() for b in deps
                   if b in ("fovexp.experiment.session", "fovexp.experiment.options")
                   and _room(a) in ROOMS)
    assert users == []


def test_the_room_check_sees_an_upward_import(graph):
    """The check itself: a task that wrote its rows through ``records`` would be caught."""
    fake = {**graph, "fovexp.experiment.tasks.adjust":
            graph["fovexp.experiment.tasks.adjust"] | {"fovexp.experiment.records.rows"}}
    with pytest.raises(AssertionError):
        test_the_rooms_import_downwards(fake)


def test_the_evaluation_uses_the_public_api(graph):
    """``fovexp.evaluation`` (the paper's analyses of outputs and stereo, section 6) imports of
    the enhancer only its public names; besides its own modules it reads trial logs through
    ``fovexp.results``, takes the t-test and the validation summary from ``fovexp.analysis``
    and the gaze argument's parser from ``fovexp.cli``; it never imports the runner."""
    assert _edges(graph, "fovexp.evaluation", "fovexp.experiment") == []
    allowed = ("fovexp.evaluation", "fovexp.results", "fovexp.analysis.stats",
               "fovexp.analysis.validation", "fovexp.cli")
    bad = [(a, b) for a, b in _edges(graph, "fovexp.evaluation", "fovexp")
           if not (b == "fovexp" or any(b == p or b.startswith(p + ".") for p in allowed))]
    assert bad == []
    # and nothing below it imports it (only the command line registers it, by name; fovexp
    # compile runs its kernel)
    users = [a for a, deps in graph.items() for b in deps
             if b.startswith("fovexp.evaluation")
             and not a.startswith(("fovexp.evaluation", "fovexp.warmup"))]
    assert users == []


def test_the_rig_check_sits_on_the_runner(graph):
    """``fovexp.rig`` measures with the session's own parts (``fovexp.experiment``, its stimuli),
    the logs layer and the enhancer's public API; nothing below it imports it (a session reads its
    reports through ``fovexp.results``)."""
    allowed = ("fovexp.results", "fovexp.experiment", "fovexp.stimuli", "fovexp.rig")
    bad = [(a, b) for a, b in _edges(graph, "fovexp.rig", "fovexp")
           if not (b == "fovexp" or any(b == p or b.startswith(p + ".") for p in allowed))]
    assert bad == []
    for part in ("fovexp.experiment", "fovexp.results", "fovexp.analysis"):
        assert _edges(graph, part, "fovexp.rig") == []


def test_the_export_reads_through_the_logs_layer(graph):
    """``fovexp.export`` (``fovexp export bids``) reads the logs through ``fovexp.results``
    (where the dataset's layout is defined, for the reader too) and runs the analysis for the
    dataset's derivatives; it never imports the runner, and nothing but the command line,
    by name, imports it."""
    assert _edges(graph, "fovexp.export", "fovexp.experiment") == []
    allowed = ("fovexp.export", "fovexp.results", "fovexp.analysis")
    bad = [(a, b) for a, b in _edges(graph, "fovexp.export", "fovexp")
           if not (b == "fovexp" or any(b == p or b.startswith(p + ".") for p in allowed))]
    assert bad == []
    users = [a for a, deps in graph.items() for b in deps
             if b.startswith("fovexp.export") and not a.startswith("fovexp.export")]
    assert users == []


def test_every_subpackage_is_in_the_wheel():
    """pyproject.toml lists the packages explicitly (its data folders are mapped into
    fovexp): a new subpackage left out of the list would be missing from the wheel."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    code = {module_name(p.parent / "__init__.py") for p in PACKAGE.rglob("__init__.py")}
    assert code <= listed, sorted(code - listed)
    for pkg, folder in conf["package-dir"].items():
        assert (ROOT / folder).is_dir(), (pkg, folder)


def test_the_lazy_public_names_are_one_list():
    """``fovexp/__init__.py`` imports its public names on first use (``_PUBLIC``: name ->
    module), lists them for type checkers (imports under ``TYPE_CHECKING``, which this walker
    reads as the package's edges) and in ``__all__``: the three agree, and each name resolves
    to the object its module defines."""
    import importlib

    import fovexp

    tree = ast.parse((PACKAGE / "__init__.py").read_text())
    typed: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom) and imp.level == 1
                typed.update({a.name: imp.module for a in imp.names})
    assert typed == fovexp._PUBLIC
    assert sorted(fovexp.__all__) == sorted([*fovexp._PUBLIC, "__version__"])
    for name, module in fovexp._PUBLIC.items():
        assert getattr(fovexp, name) is getattr(importlib.import_module(f"fovexp.{module}"), name)
    with pytest.raises(AttributeError):
        fovexp.no_such_name  # noqa: B018
