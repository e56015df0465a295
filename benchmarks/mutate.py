"""Mutation testing of the enhancer's stage modules, fovexp/results/ and the analysis'
statistics (issue 19), with cosmic-ray, one module at a time, each with the tests that
exercise it. The record is benchmarks/MUTATION.md (its table is rewritten between markers;
the text around it is kept); each module's survivors, with their diffs, go to
benchmarks/mutation/<module>.survivors.txt.

    .venv/bin/python benchmarks/mutate.py [MODULE ...] [--list] [--recheck] [--max N]

``./dev mutate`` runs it under ``nice -n 19``. MODULE is a name of :data:`MODULES` (e.g.
``contrast``, ``results.stats``); none: all of them (hours on 2 cores: run a few at a time).

Why cosmic-ray and not mutmut 3 (checked on mutmut 3.8.1): mutmut rewrites each function into
a trampoline and skips every decorated function (mutmut/mutation/file_mutation.py, "ignore
decorated functions"), so none of the 60-odd ``@numba.njit`` kernels, where most of the
formulas are, would be mutated. cosmic-ray mutates the module's syntax tree wherever the
node is, writes each mutant to disk in a copy of the repository and runs a command.

Why ``NUMBA_DISABLE_JIT=1`` for the modules with kernels (:data:`KERNEL_MODULES`): with the
JIT on, a mutated file invalidates Numba's cache of every kernel of its module (the cache is
keyed on the file), so each mutant would recompile them (seconds to tens of seconds each);
with it off the kernels run as Python (``prange`` is ``range``), which the tests' small
images keep fast enough. The mutants are the same code. The other modules run with the JIT
on: their tests load the kernels from Numba's cache, which a mutant there does not touch.

``--recheck`` runs the survivors of a module's last session again, against the tests as they
are now: tests are only added to kill survivors, so what was killed stays killed.

Operators: one replacement per operator, as mutmut makes them (+ -, * /, < <=, == !=, and,
or, True False, numbers +-1, break continue, a loop's body skipped, ``not`` added or
removed, a unary minus removed, an exception type replaced, a decorator removed). Left out
before the run, as equivalent by construction:

- mutations inside a ``@numba.njit(...)`` decorator, or removing it: the kernels' compile
  options (cache, parallel, nogil, inline, fastmath = FASTMATH, which is off) change speed,
  not values, and with the JIT off the decorator is not applied at all;
- mutations inside type annotations: with ``from __future__ import annotations`` they are
  never evaluated;
- lines marked ``# pragma: no mutate``.

Score = killed / (killed + survived); a mutant that times out (an endless loop) or breaks the
import counts as killed, as cosmic-ray counts it.
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import platform
import random
import shlex
import shutil
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from fovexp.bench import machine_cpu

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- mutation-run: begin -->", "<!-- mutation-run: end -->"

E = "tests/enhancer/"
#: The modules with Numba kernels: mutated with the JIT off (see the module docstring).
KERNEL_MODULES = {"geometry", "foveation", "contrast", "pyramids", "gabor", "colour"}
#: module name -> (file, the tests that exercise it: pytest arguments). A kernel module's
#: selection is of tests on small images (its kernels run as Python: the tests on frames of
#: 270 x 480 and more, which take minutes so, are left out; each has a small counterpart);
#: the others run with the JIT on, their kernels loaded from Numba's cache (compiled once,
#: by the baseline run).
MODULES: dict[str, tuple[str, list[str]]] = {
    "geometry": ("fovexp/geometry.py", [E + "test_geometry.py",
                                        "-k", "not point_formulas_on_the_grid"]),
    "acuity": ("fovexp/acuity.py", [E + "test_frequency.py"]),
    "foveation": ("fovexp/foveation.py", [
        E + "test_foveation.py", "-k", "not fast_foveation_error_against and not "
        "leaves_sigma_zero_pixels_bit_exact and not map_of_some_blocks_is_the_whole"]),
    "contrast": ("fovexp/contrast.py", [E + "test_contrast.py"]),
    "pyramids": ("fovexp/pyramids.py", [E + "test_pyramids.py"]),
    "frequency": ("fovexp/frequency.py", [E + "test_frequency.py"]),
    "amplitude": ("fovexp/amplitude.py", [E + "test_amplitude.py"]),
    "orientation": ("fovexp/orientation.py", [E + "test_orientation.py"]),
    "gabor": ("fovexp/gabor.py", [E + "test_gabor.py", "-k", "not std_over_k"]),
    "colour": ("fovexp/colour.py", [E + "test_colour.py"]),
    "results.calibration": ("fovexp/results/calibration.py",
                            ["tests/results/test_calibration.py"]),
    "results.derive": ("fovexp/results/derive.py", ["tests/results/test_calibration.py"]),
    "results.format": ("fovexp/results/format.py", ["tests/results/test_format.py",
                                                    "tests/results/test_loading.py",
                                                    "tests/results/test_frames.py"]),
    "results.frames": ("fovexp/results/frames.py", ["tests/results/test_frames.py"]),
    "results.limits": ("fovexp/results/limits.py", ["tests/results/test_limits.py",
                                                    "tests/results/test_stats.py",
                                                    "tests/results/test_loading.py"]),
    "results.blanking": ("fovexp/results/blanking.py", ["tests/results/test_frames.py"]),
    "results.live": ("fovexp/results/live.py", ["tests/results/test_live.py"]),
    "results.rigcheck": ("fovexp/results/rigcheck.py", ["tests/rig/test_checks.py"]),
    "results.loading": ("fovexp/results/loading.py", ["tests/results/test_loading.py"]),
    "results.stats": ("fovexp/results/stats.py", ["tests/results/test_stats.py",
                                                  "tests/analysis/test_stats.py",
                                                  "tests/results/test_calibration.py"]),
    "analysis.stats": ("fovexp/analysis/stats.py", ["tests/analysis/test_stats.py"]),
    "analysis.validation": ("fovexp/analysis/validation.py",
                            ["tests/analysis/test_validation.py"]),
}
#: cosmic-ray's sessions (one SQLite file per module), kept for --recheck
STATE = ROOT / "out" / "mutate"

#: The operators run (cosmic-ray's names without "core/"): one replacement per operator.
KEEP_OPERATORS = {
    "ReplaceBinaryOperator_Add_Sub", "ReplaceBinaryOperator_Sub_Add",
    "ReplaceBinaryOperator_Mul_Div", "ReplaceBinaryOperator_Div_Mul",
    "ReplaceBinaryOperator_FloorDiv_Div", "ReplaceBinaryOperator_Mod_Div",
    "ReplaceBinaryOperator_Pow_Mul", "ReplaceBinaryOperator_LShift_RShift",
    "ReplaceBinaryOperator_RShift_LShift", "ReplaceBinaryOperator_BitAnd_BitOr",
    "ReplaceBinaryOperator_BitOr_BitAnd", "ReplaceBinaryOperator_BitXor_BitAnd",
    "ReplaceComparisonOperator_Eq_NotEq", "ReplaceComparisonOperator_NotEq_Eq",
    "ReplaceComparisonOperator_Lt_LtE", "ReplaceComparisonOperator_LtE_Lt",
    "ReplaceComparisonOperator_Gt_GtE", "ReplaceComparisonOperator_GtE_Gt",
    "ReplaceComparisonOperator_Is_IsNot", "ReplaceComparisonOperator_IsNot_Is",
    "ReplaceComparisonOperator_In_NotIn", "ReplaceComparisonOperator_NotIn_In",
    "ReplaceUnaryOperator_Delete_USub", "ReplaceUnaryOperator_Delete_Not",
    "ReplaceUnaryOperator_Delete_Invert", "AddNot", "ReplaceTrueWithFalse",
    "ReplaceFalseWithTrue", "ReplaceAndWithOr", "ReplaceOrWithAnd",
    "ReplaceBreakWithContinue", "ReplaceContinueWithBreak", "ZeroIterationForLoop",
    "NumberReplacer", "ExceptionReplacer", "RemoveDecorator",
}


def machine() -> str:
    cpu = machine_cpu()
    return f"{cpu}, {os.cpu_count()} cores, {platform.platform()}, Python " \
           f"{platform.python_version()}"


def load() -> str:
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "?"


def copy_tree(work: Path) -> None:
    """The repository's files (tracked, and new ones git does not ignore) into ``work``."""
    if work.exists():
        shutil.rmtree(work)
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                           cwd=ROOT, capture_output=True, check=True).stdout.split(b"\0")
    for name in files:
        if not name:
            continue
        src = ROOT / os.fsdecode(name)
        if src.is_file():
            dst = work / os.fsdecode(name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    # bytecode of everything once (cosmic-ray runs each test command without writing any)
    subprocess.run([sys.executable, "-m", "compileall", "-q", "fovexp", "tests"], cwd=work,
                   check=True, stdout=subprocess.DEVNULL)


def equivalent_spans(path: Path) -> list[tuple[tuple[int, int], tuple[int, int], str]]:
    """Source spans whose mutations are equivalent by construction (module docstring)."""
    tree = ast.parse(path.read_text())
    spans = []

    def span(node: ast.AST, why: str) -> None:
        spans.append(((node.lineno, node.col_offset), (node.end_lineno, node.end_col_offset),
                      why))

    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for dec in node.decorator_list:
                if "numba" in ast.unparse(dec):
                    # from the "@" (one column before the expression) to its end
                    spans.append(((dec.lineno, max(dec.col_offset - 1, 0)),
                                  (dec.end_lineno, dec.end_col_offset), "numba decorator"))
            if node.returns is not None:
                span(node.returns, "annotation")
            args = node.args
            for a in [*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg,
                      args.kwarg]:
                if a is not None and a.annotation is not None:
                    span(a.annotation, "annotation")
        elif isinstance(node, ast.AnnAssign):
            span(node.annotation, "annotation")
    for i, line in enumerate(path.read_text().splitlines(), start=1):
        if "pragma: no mutate" in line:
            spans.append(((i, 0), (i, len(line) + 1), "pragma: no mutate"))
    return spans


def inside(start: tuple[int, int], end: tuple[int, int], span) -> bool:
    (a, b, _) = span
    return a <= tuple(start) and tuple(end) <= b


def _skip(wdb, job_ids: list[str], why: str) -> None:
    from cosmic_ray.work_item import WorkerOutcome, WorkResult

    for job_id in job_ids:
        wdb.set_result(job_id, WorkResult(output=why, worker_outcome=WorkerOutcome.SKIPPED))


def filter_session(db: Path, module: Path, max_mutants: int | None,
                   sample: int | None = None) -> dict[str, int]:
    """Mark the mutants left out (operators not run, equivalent by construction; past
    ``max_mutants`` in a trial run; outside a random ``sample`` of that many) as skipped in
    cosmic-ray's session; returns the counts left out, by reason."""
    from cosmic_ray.work_db import WorkDB, use_db

    spans = equivalent_spans(module)
    lines = module.read_text().splitlines()
    left_out: dict[str, list[str]] = {}
    kept = []
    with use_db(db, WorkDB.Mode.open) as wdb:
        for item in wdb.pending_work_items:
            (m,) = item.mutations
            name = m.operator_name.split("/", 1)[-1]
            why = None
            if name not in KEEP_OPERATORS:
                why = "operator not run"
            elif name == "RemoveDecorator" and "numba" in lines[m.start_pos[0] - 1]:
                why = "numba decorator"
            else:
                why = next((s[2] for s in spans if inside(m.start_pos, m.end_pos, s)), None)
            if why:
                left_out.setdefault(why, []).append(item.job_id)
            else:
                kept.append((m.start_pos, item.job_id))
        kept.sort()
        if max_mutants is not None:  # a trial: the first N mutants of the file
            left_out["beyond --max"] = [j for _, j in kept[max_mutants:]]
        elif sample is not None and len(kept) > sample:  # a uniform sample, reproducible
            chosen = set(random.Random(f"{module.name}:{sample}").sample(range(len(kept)),
                                                                         sample))
            left_out["not in the sample"] = [j for i, (_, j) in enumerate(kept)
                                             if i not in chosen]
        for why, jobs in left_out.items():
            _skip(wdb, jobs, f"left out by benchmarks/mutate.py: {why}")
    return {why: len(jobs) for why, jobs in left_out.items()}


def outcomes(dbs: list[Path]) -> tuple[dict[str, int], list[tuple[int, str, str]]]:
    """Counts by outcome (killed, survived, incompetent, pending) over the sessions of one
    module and its survivors (line, operator, diff); each mutant counted once (a recheck's
    parts all hold the results the last run had found)."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome, WorkerOutcome

    counts = {"killed": 0, "survived": 0, "incompetent": 0, "pending": 0,
              "killed by timeout": 0, "killed by an error at import or collection": 0}
    results: dict[str, Any] = {}
    specs: dict[str, Any] = {}
    for db in dbs:
        with use_db(db, WorkDB.Mode.open) as wdb:
            specs.update({item.job_id: item.mutations[0] for item in wdb.work_items})
            results.update({job_id: r for job_id, r in wdb.results
                            if r.worker_outcome != WorkerOutcome.SKIPPED})
            counts["pending"] += wdb.num_work_items - wdb.num_results
    survivors = []
    for job_id, result in results.items():
        if result.test_outcome == TestOutcome.KILLED:  # failed, timed out or crashed
            out = result.output or ""
            if "ERROR: usage" in out or "file or directory not found" in out:
                raise SystemExit(f"{dbs[0]}: pytest was called wrongly:\n{out[-2000:]}")
            counts["killed"] += 1
            last = out.strip().splitlines()[-1] if out.strip() else ""
            if out == "timeout":
                counts["killed by timeout"] += 1
            elif "error" in last and "failed" not in last:
                counts["killed by an error at import or collection"] += 1
        elif result.test_outcome == TestOutcome.SURVIVED:
            counts["survived"] += 1
            m = specs[job_id]
            survivors.append((m.start_pos[0], m.operator_name, result.diff or ""))
        else:
            counts["incompetent"] += 1
    return counts, sorted(survivors)


def _split(db: Path, parts: int) -> list[Path]:
    """Copies of a session, the pending mutants dealt round-robin: part i skips the others'."""
    from cosmic_ray.work_db import WorkDB, use_db

    with use_db(db, WorkDB.Mode.open) as wdb:
        pending = sorted((item.mutations[0].start_pos, item.job_id)
                         for item in wdb.pending_work_items)
    out = []
    for i in range(parts):
        part = db.with_name(f"{db.stem}.part{i}.sqlite")
        shutil.copy(db, part)
        with use_db(part, WorkDB.Mode.open) as wdb:
            _skip(wdb, [j for k, (_, j) in enumerate(pending) if k % parts != i],
                  "another part's")
        out.append(part)
    return out


def run_module(name: str, works: list[Path], env: dict[str, str], max_mutants: int | None,
               recheck: bool, sample: int | None = None) -> dict:
    """Mutation-test one module, its mutants shared among ``works`` (copies of the
    repository, one cosmic-ray session each, run side by side): a new session, or with
    ``recheck`` the survivors of the last one again (against the tests as they are now)."""
    import sqlite3

    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    path, tests = MODULES[name]
    if name in KERNEL_MODULES:
        env = dict(env, NUMBA_DISABLE_JIT="1")
    cr = str(Path(sys.executable).with_name("cosmic-ray"))
    # the command cosmic-ray runs (it splits it with shlex): the baseline runs the same words
    command = shlex.join([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                          "-m", "not slow and not gui", *tests])
    pytest = shlex.split(command)
    for work in works:  # in every copy: with the JIT on, this compiles its kernels' cache
        base = subprocess.run(pytest, cwd=work, env=env, capture_output=True, text=True)
        if base.returncode != 0:
            raise SystemExit(f"{name}: the tests fail without a mutation:\n"
                             f"{base.stdout[-3000:]}")
    t0 = time.perf_counter()
    subprocess.run(pytest, cwd=works[0], env=env, capture_output=True, check=True)
    baseline_s = time.perf_counter() - t0
    # generous (a loaded machine); an endless loop is killed here, and counts as killed
    timeout = max(60.0, 5.0 * baseline_s)
    STATE.mkdir(parents=True, exist_ok=True)
    cfg, db = STATE / f"{name}.toml", STATE / f"{name}.sqlite"
    cfg.write_text(
        "[cosmic-ray]\n"
        f'module-path = "{path}"\n'
        f"timeout = {timeout:.0f}\n"
        "excluded-modules = []\n"
        f"test-command = {json.dumps(command)}\n"
        '[cosmic-ray.distributor]\nname = "local"\n')
    previous = json.loads((STATE / f"{name}.json").read_text()) if recheck else None
    if recheck:
        if not db.exists():
            raise SystemExit(f"{name}: no session to recheck ({db}): run it first")
        # the parts' results back into the whole session, the survivors made pending again
        merged = []
        for part in sorted(STATE.glob(f"{name}.part*.sqlite")):
            with use_db(part, WorkDB.Mode.open) as wdb:
                merged += [(j, r) for j, r in wdb.results if r.output != "another part's"]
        con = sqlite3.connect(db)
        con.execute("delete from work_results")
        con.commit()
        con.close()
        with use_db(db, WorkDB.Mode.open) as wdb:
            for job_id, r in merged:
                if r.test_outcome != TestOutcome.SURVIVED:
                    wdb.set_result(job_id, r)
        left_out, sample = previous["left_out"], previous.get("sample")
    else:
        db.unlink(missing_ok=True)
        subprocess.run([cr, "init", str(cfg), str(db)], cwd=works[0], env=env, check=True,
                       capture_output=True)
        left_out = filter_session(db, works[0] / path, max_mutants, sample)
    for old in STATE.glob(f"{name}.part*.sqlite"):
        old.unlink()
    parts = _split(db, len(works))
    t0 = time.perf_counter()
    procs = [subprocess.Popen([cr, "exec", str(cfg), str(part)], cwd=work, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for work, part in zip(works, parts, strict=True)]
    if any(p.wait() != 0 for p in procs):
        raise SystemExit(f"{name}: cosmic-ray exec failed")
    wall_s = time.perf_counter() - t0
    counts, survivors = outcomes(parts)
    killed, survived = counts["killed"], counts["survived"]
    out = ROOT / "benchmarks" / "mutation"
    out.mkdir(exist_ok=True)
    with open(out / f"{name}.survivors.txt", "w") as fh:
        fh.write(f"# {name} ({path}): {survived} surviving mutants of {killed + survived} "
                 f"(benchmarks/MUTATION.md says which are equivalent)\n")
        for line, op, diff in survivors:
            fh.write(f"\n## line {line}: {op}\n{diff}\n")
    result = {
        "module": name, "path": path, "tests": tests, "jit": name not in KERNEL_MODULES,
        "mutants": killed + survived, "killed": killed, "survived": survived,
        "incompetent": counts["incompetent"], "pending": counts["pending"],
        "killed_by_timeout": counts["killed by timeout"],
        "killed_by_error": counts["killed by an error at import or collection"],
        "left_out": left_out, "score": round(100.0 * killed / max(killed + survived, 1), 1),
        "score_95": wilson(killed, killed + survived),
        "population": killed + survived + counts["incompetent"]
        + left_out.get("not in the sample", 0),
        "baseline_s": round(baseline_s, 1), "wall_s": round(wall_s), "timeout_s": timeout,
        "workers": len(works),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine(), "load": load(), "max": max_mutants, "sample": sample,
        "command": f"./dev mutate {'--recheck ' if recheck else ''}{name}",
    }
    if previous:  # what the first run found, kept beside the recheck
        result["first_run"] = previous.get("first_run") or {
            k: previous[k] for k in ("mutants", "killed", "survived", "score", "date", "wall_s",
                                     "load")}
        result["wall_s"] += previous.get("wall_s", 0)
    (STATE / f"{name}.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson interval (percent) of a proportion k / n: the score of a sample's
    population."""
    if n == 0:
        return (0.0, 100.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / (1 + z * z / n)
    return (round(100 * (centre - half), 1), round(100 * (centre + half), 1))


def write_record(results: dict[str, dict]) -> None:
    """The table of benchmarks/MUTATION.md, between its markers (the text around is kept)."""
    path = ROOT / "benchmarks" / "MUTATION.md"
    text = path.read_text() if path.exists() else f"# Mutation testing\n\n{BEGIN}\n{END}\n"
    rows = ["| module | mutants run (of all) | first run: killed / survived | killed | survived "
            "| score (95 % interval) | left out as equivalent | wall | date (UTC) | load | "
            "command |", "|---|---:|---:|---:|---:|---|---:|---:|---|---:|---|"]
    for name in MODULES:
        r = results.get(name)
        if r is None:
            continue
        run = r["mutants"] + r.get("incompetent", 0)
        of = f" of {r['population']}" if r.get("population", run) != run else ""
        if r.get("max"):
            of = f" (first {r['max']})"
        lo, hi = r.get("score_95", (None, None))
        interval = f" ({lo}-{hi})" if of and lo is not None else ""
        equivalent = sum(v for k, v in r["left_out"].items()
                         if k in ("numba decorator", "annotation", "pragma: no mutate"))
        cmd = "./dev mutate" + (f" --sample {r['sample']}" if r.get("sample") else "") + \
            f" {name}" + (", then --recheck" if r.get("first_run") else "")
        first = r.get("first_run") or r
        rows.append(
            f"| {name} | {run}{of} | {first['killed']} / {first['survived']} | {r['killed']} | "
            f"{r['survived']} | "
            f"{r['score']} %{interval} | {equivalent} | {r['wall_s'] / 60:.0f} min | "
            f"{r['date'][:16]} | {r['load']} | `{cmd}` |")
    machines = sorted({r["machine"] for r in results.values()})
    table = "\n".join(rows) + "\n\nMachine: " + "; ".join(machines) + \
        ". Under `nice -n 19`, two copies side by side; load: the 1-minute load average when " \
        "the module finished (the machine is shared)."
    head, _, rest = text.partition(BEGIN)
    _, _, tail = rest.partition(END)
    path.write_text(f"{head}{BEGIN}\n{table}\n{END}{tail}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", help="names of MODULES (default: all)")
    ap.add_argument("--list", action="store_true", help="list the modules and their tests")
    ap.add_argument("--max", type=int, default=None,
                    help="run only the first N mutants of each module (a trial; not recorded "
                    "as a full run)")
    ap.add_argument("--sample", type=int, default=None,
                    help="run a uniform random sample of N mutants of each module (reproducible; "
                    "the record gives the score's 95 %% interval)")
    ap.add_argument("--recheck", action="store_true",
                    help="run the survivors of the last run of each module again, against the "
                    "tests as they are now")
    ap.add_argument("--work", type=Path, default=Path("/tmp/fovexp-mutate"),
                    help="folder of the scratch copies of the repository the mutants are "
                    "written into")
    ap.add_argument("--workers", type=int, default=2,
                    help="copies run side by side, each with a share of the mutants (2: the "
                    "machine's cores)")
    args = ap.parse_args()
    if args.list:
        for name, (path, tests) in MODULES.items():
            print(f"{name:22s} {path:34s} {' '.join(tests)}")
        return 0
    names = args.modules or list(MODULES)
    unknown = [n for n in names if n not in MODULES]
    if unknown:
        ap.error(f"unknown module(s) {', '.join(unknown)} (see --list)")
    works = [args.work / f"w{i}" for i in range(args.workers)]
    for work in works:
        copy_tree(work)
    stimuli = args.work / "dry-run-scenes"  # the tests' FOVEXP_TEST_STIMULI, made once
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1", FOVEXP_TEST_STIMULI=str(stimuli))
    env.pop("NUMBA_DISABLE_JIT", None)
    if not stimuli.is_dir():
        subprocess.run([sys.executable, "-c",
                        "import sys; from fovexp.stimuli.folder import DRY_RUN_SIZE, "
                        "StimulusSet, generate_scenes; generate_scenes(StimulusSet(sys.argv[1]), "
                        "DRY_RUN_SIZE)", str(stimuli)], cwd=works[0], check=True)
    record = ROOT / "benchmarks" / "mutation" / "results.json"
    results = json.loads(record.read_text()) if record.exists() else {}
    for name in names:
        print(f"mutate {name}: {MODULES[name][0]} ...", flush=True)
        r = run_module(name, works, env, args.max, args.recheck, args.sample)
        print(f"  {r['killed']} killed, {r['survived']} survived of {r['mutants']} "
              f"({r['score']} %), {sum(r['left_out'].values())} left out, "
              f"{r['wall_s'] / 60:.0f} min", flush=True)
        results[name] = r
        record.parent.mkdir(exist_ok=True)
        record.write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
        write_record(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
