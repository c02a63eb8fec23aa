"""``spotlab hil``: run a hardware-in-the-loop scenario, or list the shipped ones."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from spotlab.console.device_settings import FAMILY_SETTINGS
from spotlab.console.errors import EXIT_FAILURE, CommandError

HELP = "run a hardware-in-the-loop scenario of simulators, or list the shipped ones"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "hil",
        help=HELP,
        description="Hardware-in-the-loop scenarios (docs/hil.md): every simulator of the "
        "scenario runs as its own process on a real pty or TCP port, spotlab record records "
        "them, the processing steps run as spotlab export does, and everything is scored "
        "against the simulators' truth at the end. Exit 1 when a criterion fails.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", help="run or list")
    actions.required = True
    run = actions.add_parser("run", help="run a scenario file (or a shipped scenario's name)")
    run.add_argument("scenario", help="SCENARIO.toml, or the name of a shipped scenario")
    run.add_argument(
        "--report", type=Path, metavar="DIR",
        help="folder of the report, recording and truth (default hil-NAME)",
    )  # fmt: skip
    run.add_argument("--junit", type=Path, metavar="FILE", help="JUnit XML (default DIR/junit.xml)")
    run.add_argument("--seed", type=int, help="seed of the simulators (default the scenario's)")
    run.add_argument("--json", action="store_true", help="print the summary as JSON")
    run.set_defaults(run=_run)
    listing = actions.add_parser("list", help="list the shipped scenarios")
    listing.add_argument("--json", action="store_true", help="as JSON")
    listing.set_defaults(run=_list)


def _list(args: argparse.Namespace) -> int:
    import json

    from spotlab.hil.catalog import describe, shipped

    rows = []
    for stem, path in shipped().items():
        name, duration, description = describe(path)
        rows.append({"name": stem, "title": name, "duration_s": duration,
                     "description": description, "path": str(path)})  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        print(f"{r['name']:<14} {r['duration_s']:>7g} s  {r['description']}")
    return 0


def _run(args: argparse.Namespace) -> int:
    import json

    from spotlab.hil.catalog import resolve
    from spotlab.hil.runner import run_scenario
    from spotlab.hil.scenario import load_scenario

    path = resolve(args.scenario)
    settings = {family: tuple(table) for family, table in FAMILY_SETTINGS.items()}
    scenario = load_scenario(path, settings)
    folder = args.report or Path(f"hil-{path.stem}")
    if folder.exists() and not folder.is_dir():
        raise CommandError(f"--report {folder}: is a file, not a folder")
    if args.junit is not None and args.junit.is_dir():
        raise CommandError(f"--junit {args.junit}: is a folder, not a file")
    summary = run_scenario(
        scenario, folder, seed=args.seed, junit=args.junit,
        progress=lambda line: print(line, file=sys.stderr, flush=True),
    )  # fmt: skip
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"scenario {summary['scenario']} (seed {summary['seed']})")
        if summary["problem"]:
            print(f"  problem  {summary['problem']}")
        for c in summary["criteria"]:
            print(f"  {'pass' if c['passed'] else 'FAIL'}  {c['criterion']}  (got {c['value']})")
        print(f"report {folder / 'report.html'}")
        print(f"verdict {summary['verdict']}")
    return 0 if summary["verdict"] == "pass" else EXIT_FAILURE
