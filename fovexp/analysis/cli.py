"""``fovexp analyze results/ --out report/`` (paper sections 5.3, 6.1): ``fovexp.cli`` registers
:func:`add_analyze_parser`; ``python -m fovexp.analysis`` does the same."""

from __future__ import annotations

import argparse
import shutil
import sys
import warnings
from pathlib import Path

from fovexp import FovexpError
from fovexp.results.limits import add_limit_options, limits_from_args


def _configure(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("results", type=Path,
                   help="results folder (<experiment>/<participant>/trials.csv), or one "
                        "experiment's folder")
    p.add_argument("--out", type=Path, default=Path("report"),
                   help="output folder for report.md, report.html, tables/, figures/ "
                        "(default: report)")
    p.add_argument("--include-incomplete", action="store_true",
                   help="keep incomplete sessions (rule R10 then only reports them)")
    p.add_argument("--include-pilots", action="store_true",
                   help="keep mouse-gaze pilot sessions (rule R7 leaves them out)")
    p.add_argument("--protocol", action="append", default=[], metavar="EXPERIMENT=SHA256",
                   help="keep this protocol version (hash or prefix) of an experiment instead "
                        "of the majority one (rule R9); repeatable")
    add_limit_options(p)
    p.add_argument("--no-figures", action="store_true", help="skip the PNG/PDF figures")
    p.add_argument("--table-out", type=Path, default=None,
                   help="also write the calibrated Table 2 (ParameterTable YAML) here")
    p.set_defaults(func=analyze_command)
    return p


def add_analyze_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``analyze`` sub-command to ``fovexp``'s parser."""
    p = subparsers.add_parser(
        "analyze", help="turn trial logs into the paper's results (Table 2, validation tests)",
        description="Load and validate trial logs, compute the calibration (Table 2) and "
                    "validation statistics, write tables, figures, report.md and report.html "
                    "(the same report as a page).",
    )
    return _configure(p)


def analyze_command(args: argparse.Namespace) -> int:
    """Run the analysis; on :class:`FovexpError` print one error line and return 2."""
    from .report import analyze  # matplotlib etc. only when the command runs

    try:
        protocol = {}
        for item in args.protocol:
            exp, sep, sha = item.partition("=")
            if not sep or not exp or not sha:
                raise FovexpError(f"--protocol {item!r}: expected EXPERIMENT=SHA256")
            protocol[exp] = sha
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            limits = limits_from_args(args)
            ana = analyze(args.results, args.out, include_incomplete=args.include_incomplete,
                          include_pilots=args.include_pilots, protocol=protocol,
                          limits=limits, figures=not args.no_figures)
        for w in caught:
            print(f"warning: {w.message}", file=sys.stderr)
        if args.table_out is not None:
            if ana.calibration is None:
                raise FovexpError("--table-out: no Table 2 (calibration-fe, -sk and -sf are all "
                                  "needed)")
            # The same file as the report's table2.yaml (one table, one source string).
            shutil.copyfile(ana.out / "table2.yaml", args.table_out)
    except FovexpError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    n_excl = sum(e.n_trials for e in ana.data.exclusions if e.rule != "note")
    print(f"analysed {len(ana.data.trials)} trials ({n_excl} excluded, see the report's "
          f"exclusions); report: {ana.report} and {ana.report.with_suffix('.html')}")
    if ana.calibration is not None:
        print(f"Table 2 (ParameterTable): {ana.out / 'table2.yaml'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m fovexp.analysis``: the same as ``fovexp analyze``."""
    parser = _configure(argparse.ArgumentParser(prog="python -m fovexp.analysis",
                                                description="fovexp analyze"))
    args = parser.parse_args(argv)
    return analyze_command(args)
