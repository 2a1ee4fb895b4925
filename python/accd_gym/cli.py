"""Command-line entry point ``accd-gym``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Optional, Sequence


def _settle(args: argparse.Namespace) -> int:
    from accd_gym import settle

    summary = settle.run(Path(args.out), preset=args.preset, duration=args.duration, progress=not args.quiet)
    keys = ["final_depth_m", "final_trail_m", "settling_time_s", "final_attachment_tension_N"]
    print(json.dumps({k: round(summary[k], 3) for k in keys}, indent=2))
    print(f"wrote {Path(args.out) / 'settle.png'} and {Path(args.out) / 'summary.json'}")
    return 0


def _study(args: argparse.Namespace) -> int:
    from accd_gym import study

    out = Path(args.out)
    docs = study.run(args.studies, out, progress=not args.quiet, dpi=args.dpi)
    for name, doc in docs.items():
        print(f"{name}: wrote {', '.join(str(out / f) for f in doc['figures'])}, {out / (name + '.json')}, {out / (name + '.md')}")
    if len(docs) > 1:
        print(f"all tables: {out / 'summary.md'}")
    return 0


def _export_aero(args: argparse.Namespace) -> int:
    from accd_gym import default_aero_table_json

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(default_aero_table_json())
    print(f"wrote the default ACCD aerodynamic tables to {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``accd-gym`` and its subcommands."""
    parser = argparse.ArgumentParser(prog="accd-gym", description="accd-gym: In-Air Capturing simulation tools.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("settle", help="simulate a towed tether settling behind the aircraft and plot it")
    p.add_argument("--out", default="runs/settle", help="output folder (default: runs/settle)")
    p.add_argument("--preset", default="table3", help="tether preset, e.g. table3 or steel-250m-24mm")
    p.add_argument("--duration", type=float, default=120.0, help="simulated time in seconds (default 120)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_settle)
    from accd_gym.study import STUDIES

    p = sub.add_parser("study", help="run the paper's section-4 tether design studies: plots, JSON, markdown tables")
    p.add_argument("studies", nargs="+", choices=[*STUDIES, "all"], metavar="STUDY",
                   help=f"one or more of: {', '.join(STUDIES)}, all")
    p.add_argument("--out", default="runs/study", help="output folder (default: runs/study)")
    p.add_argument("--dpi", type=int, default=90, help="resolution of the PNGs (default 90)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_study)
    p = sub.add_parser("export-aero", help="write the default ACCD aerodynamic tables (JSON) to start your own")
    p.add_argument("--out", default="accd-aero.json", help="output file (default: accd-aero.json)")
    p.set_defaults(func=_export_aero)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Runs ``accd-gym`` with ``argv`` (default: the process arguments); returns the exit code."""
    from accd_gym.errors import AccdError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except AccdError as e:
        print(f"accd-gym: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
