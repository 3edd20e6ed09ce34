"""The ``thermo-ddp`` command line. Bad input: one line on stderr and exit status 2."""
from __future__ import annotations

import argparse
import logging
import sys

from .errors import InputError


def _demo(args) -> int:
    from .demo import hold_demo
    print(hold_demo(args.payload_kg, args.hold_s).report())
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="thermo-ddp", description=__doc__)
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress (INFO)")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="static hold of a payload by the elbow: torque, current, winding heating")
    demo.add_argument("--payload-kg", type=float, default=40.0)
    demo.add_argument("--hold-s", type=float, default=60.0)
    demo.set_defaults(run=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(name)s: %(message)s")
    try:
        return args.run(args)
    except InputError as err:
        print(f"thermo-ddp: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
