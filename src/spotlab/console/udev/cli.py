"""The command line ``spotlab udev install|show|check``: argparse hooks and text or JSON output."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from spotlab.console.errors import EXIT_FAILURE, EXIT_OK
from spotlab.console.udev.installer import DEFAULT_TARGET, install, plan_install
from spotlab.console.udev.rules import RulesFile
from spotlab.console.udev.shipped import (
    CLASSIFY_FILE,
    DEFAULT_POLICY,
    POLICIES,
    UdevError,
    check_rules,
    rules_dir,
    show_rules,
)


def add_udev_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``udev`` with ``install``, ``show`` and ``check`` to a subparsers object."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "udev",
        help="install or check the udev rules for USB-serial adapters and OAK cameras",
        description="udev rules that give the logged-in user (uaccess) or the plugdev group "
        "access to the USB-serial adapters and Luxonis OAK cameras spotlab talks to, keep "
        "ModemManager away from them, set the FTDI latency timer to 1 ms and create "
        "/dev/spotlab/<serial> links. See docs/udev.md.",
    )
    actions = parser.add_subparsers(
        dest="udev_action", metavar="ACTION", help="install, show or check"
    )
    actions.required = True

    inst = actions.add_parser(
        "install",
        help="show (or, with --yes, write) the rules files",
        description="Without --yes, only show what would be written. With --yes, write "
        f"{CLASSIFY_FILE} and the policy file into the target folder (needs root for "
        f"{DEFAULT_TARGET}).",
    )
    inst.add_argument(
        "--policy",
        choices=tuple(POLICIES),
        default=DEFAULT_POLICY,
        help="uaccess: the user at the local seat (default); plugdev: members of plugdev",
    )
    inst.add_argument(
        "--target",
        type=Path,
        default=DEFAULT_TARGET,
        metavar="DIR",
        help=f"folder to write into (default {DEFAULT_TARGET})",
    )
    inst.add_argument("--yes", action="store_true", help="really write the files")
    inst.add_argument(
        "--reload",
        action="store_true",
        help="with --yes: also run udevadm control --reload-rules and udevadm trigger",
    )
    inst.add_argument("--json", action="store_true", help="print JSON")

    show = actions.add_parser(
        "show",
        help="print the shipped rules",
        description="Print the shipped rules files; with --policy only the ones that "
        "install --policy writes.",
    )
    show.add_argument(
        "--policy",
        choices=tuple(POLICIES),
        default=None,
        help="only the files install --policy writes (default: all shipped files)",
    )
    show.add_argument("--json", action="store_true", help="print JSON")

    check = actions.add_parser(
        "check",
        help="validate udev rules files strictly",
        description="Check rules files for unknown keys, wrong operators, missing commas, "
        "unbalanced quotes, GOTO without LABEL and world-writable modes. Without FILE, "
        "check the shipped rules. Never runs udevadm.",
    )
    check.add_argument(
        "files",
        nargs="*",
        type=Path,
        metavar="FILE",
        help="rules files (default: the shipped ones)",
    )
    check.add_argument("--strict", action="store_true", help="fail on warnings too")
    check.add_argument("--json", action="store_true", help="print JSON")

    parser.set_defaults(run=run_udev)
    return parser


def run_udev(args: argparse.Namespace) -> int:
    """Run ``spotlab udev ACTION``; returns the exit code."""
    as_json = bool(getattr(args, "json", False))
    try:
        if args.udev_action == "install":
            return _run_install(args, as_json)
        if args.udev_action == "show":
            return _run_show(args, as_json)
        if args.udev_action == "check":
            return _run_check(args, as_json)
    except UdevError as exc:
        if as_json:
            print(json.dumps({"ok": False, "error": str(exc)}))
            return exc.exit_code
        raise
    raise UdevError(f"unknown udev action {args.udev_action!r}")


def _run_install(args: argparse.Namespace, as_json: bool) -> int:
    plan = plan_install(args.policy, args.target)
    result = install(plan, yes=args.yes, reload=args.reload)
    print(json.dumps(result.to_dict()) if as_json else result.to_text())
    return EXIT_OK if result.ok else EXIT_FAILURE


def _run_show(args: argparse.Namespace, as_json: bool) -> int:
    files = show_rules(args.policy)
    if as_json:
        source = str(rules_dir())
        payload = {"source": source, "files": [{"name": n, "content": c} for n, c in files]}
        print(json.dumps(payload))
        return EXIT_OK
    for index, (name, content) in enumerate(files):
        if index:
            print()
        print(f"# ==> {name} <==")
        print(content, end="" if content.endswith("\n") else "\n")
    return EXIT_OK


def _run_check(args: argparse.Namespace, as_json: bool) -> int:
    results = check_rules(args.files)
    failed = any(_fails(r, args.strict) for r in results)
    if as_json:
        print(json.dumps({"ok": not failed, "files": [r.to_dict() for r in results]}))
        return EXIT_FAILURE if failed else EXIT_OK
    for r in results:
        for issue in r.issues:
            print(issue)
        state = "FAILED" if _fails(r, args.strict) else "ok"
        print(
            f"{r.path}: {len(r.rules)} rules, {len(r.errors)} errors, "
            f"{len(r.warnings)} warnings: {state}"
        )
    return EXIT_FAILURE if failed else EXIT_OK


def _fails(result: RulesFile, strict: bool) -> bool:
    return not result.ok or bool(strict and result.warnings)
