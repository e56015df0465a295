"""``python -m fovexp.experiment run PROTOCOL --participant ID ...`` (same as ``fovexp run``)."""

import argparse
import sys

from fovexp.cli import plain_warnings

from .cli import add_run_parser


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fovexp.experiment")
    sub = parser.add_subparsers(dest="command", required=True)
    add_run_parser(sub)
    args = parser.parse_args(argv)
    plain_warnings("fovexp")
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
