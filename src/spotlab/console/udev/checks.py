"""The validations: per pair, per rule and across the file.

Per pair: unknown keys, attributes and operators a key does not take, bad
prefixes, bad substitutions, world-writable MODE, unknown OPTIONS and builtins.
Per rule: several GOTO or LABEL, a rule that assigns nothing. Across the file:
GOTO without a LABEL after it, LABEL nobody jumps to.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence

from spotlab.console.udev.keys import (
    BUILTINS,
    KEYS,
    LEGACY_KEYS,
    MATCH_OPERATORS,
    READ_ONLY_PROPERTIES,
)
from spotlab.console.udev.model import Assignment, Code, IssueLog, Rule
from spotlab.console.udev.values import format_problem, is_option, mode_bits


def check_assignment(a: Assignment, log: IssueLog) -> None:
    """Check one pair against what udev accepts for its key."""

    def err(code: Code, message: str) -> None:
        log.at(a, "error", code, message)

    def warn(code: Code, message: str) -> None:
        log.at(a, "warning", code, message)

    spec = KEYS.get(a.key)
    if spec is None:
        if a.key in LEGACY_KEYS:
            err(Code.UNKNOWN_KEY, f"unknown key '{a.key}': {LEGACY_KEYS[a.key]}")
            return
        close = difflib.get_close_matches(a.key.upper(), KEYS, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        err(Code.UNKNOWN_KEY, f"unknown key '{a.key}'{hint}")
        return

    # {attribute}
    if spec.attr == "none" and a.attr is not None:
        err(Code.BAD_ATTRIBUTE, f"{a.key} takes no {{attribute}}")
    elif spec.attr == "required" and not a.attr:
        err(Code.BAD_ATTRIBUTE, f"{a.key} needs an attribute: {a.key}{{name}}")
    elif a.attr is not None and spec.attr_values is not None and a.attr not in spec.attr_values:
        allowed = ", ".join(sorted(spec.attr_values))
        err(Code.BAD_ATTRIBUTE, f"{a.key}{{{a.attr}}}: attribute must be one of {allowed}")
    elif a.key == "TEST" and a.attr and mode_bits(a.attr) is None:
        err(Code.BAD_ATTRIBUTE, f"TEST{{{a.attr}}}: the attribute is an octal mode mask")
    elif a.key in ("ATTR", "ATTRS", "SYSCTL") and a.attr:
        problem = format_problem(a.attr)
        if problem:
            err(Code.BAD_ATTRIBUTE, f"{a.key}{{{a.attr}}}: {problem[1]}")

    # operator
    if a.op not in spec.ops:
        if a.op in spec.coerced:
            warn(
                Code.BAD_OPERATOR,
                f"{a.key} does not take '{a.op}'; udev treats it as '=' ({spec.takes})",
            )
        elif spec.ops <= MATCH_OPERATORS:
            err(Code.BAD_OPERATOR, f"{a.key} is a match key and takes '==' or '!=', not '{a.op}'")
        else:
            err(Code.BAD_OPERATOR, f"{a.key} does not take '{a.op}' ({spec.takes})")

    # prefixes
    if "i" in a.prefix:
        if a.op not in MATCH_OPERATORS:
            err(Code.BAD_PREFIX, f"prefix 'i' (case-insensitive) needs '==' or '!=', not '{a.op}'")
        elif not spec.case_prefix:
            err(Code.BAD_PREFIX, f"{a.key} does not take the prefix 'i'")

    # value
    assigning = not a.is_match
    checked = spec.check_value == "always" or (spec.check_value == "assign" and assigning)
    if spec.nonempty and (assigning or spec.check_value == "always") and not a.value:
        warn(Code.BAD_VALUE, f"{a.key} has an empty value")
    elif checked:
        problem = format_problem(a.value)
        if problem:
            err(Code.BAD_VALUE, f'{a.key}="{a.value}": {problem[1]}')

    if a.key == "MODE" and assigning:
        _check_mode(a, log)
    elif a.key == "OPTIONS":
        if not is_option(a.value):
            err(
                Code.BAD_VALUE,
                f'OPTIONS="{a.value}" is not a udev option; udev ignores it '
                "(one option per OPTIONS key)",
            )
    elif a.key == "ENV" and assigning and a.attr in READ_ONLY_PROPERTIES:
        err(
            Code.BAD_ATTRIBUTE,
            f"ENV{{{a.attr}}} is set by the kernel or udev and cannot be assigned",
        )
    elif a.key == "NAME" and assigning and a.value in ("", "%k"):
        err(Code.BAD_VALUE, f'NAME="{a.value}" has no effect; udev ignores it')
    elif a.key == "SUBSYSTEM" and a.value in ("bus", "class"):
        warn(Code.BAD_VALUE, f'SUBSYSTEM=="{a.value}" should be written "subsystem"')
    elif a.key in ("IMPORT", "RUN") and a.attr == "builtin":
        command = a.value.split(maxsplit=1)[0] if a.value.strip() else ""
        if command not in BUILTINS:
            err(Code.BAD_VALUE, f"unknown udev builtin '{command}'")


def _check_mode(a: Assignment, log: IssueLog) -> None:
    bits = mode_bits(a.value)
    if bits is None:
        log.at(a, "error", Code.BAD_VALUE, f'MODE="{a.value}" is not an octal mode such as "0660"')
        return
    if bits & 0o002:
        log.at(
            a,
            "error",
            Code.WORLD_WRITABLE,
            f'MODE="{a.value}" makes the device writable by every user; use TAG+="uaccess" '
            'or MODE="0660" with GROUP=',
        )
    if bits & 0o7000:
        log.at(
            a,
            "warning",
            Code.BAD_VALUE,
            f'MODE="{a.value}" sets setuid/setgid/sticky bits, which mean nothing on a device node',
        )


def check_rule(rule: Rule, had_errors: bool, log: IssueLog) -> None:
    """Several GOTO or LABEL in one rule; a rule that only matches (if it parsed clean)."""
    gotos = rule.get("GOTO")
    labels = rule.get("LABEL")
    if len(gotos) > 1:
        log.at(gotos[1], "warning", Code.MULTIPLE_GOTO, "more than one GOTO; udev uses the first")
    if len(labels) > 1:
        log.at(labels[1], "warning", Code.MULTIPLE_LABEL, "more than one LABEL; udev uses the last")
    if had_errors or not rule.assignments:
        return
    effect = any(
        (not a.is_match and a.key in KEYS) or a.key in ("PROGRAM", "IMPORT")
        for a in rule.assignments
    )
    if not effect:
        log.at(
            rule.assignments[0],
            "warning",
            Code.NO_EFFECT,
            "rule only matches and assigns nothing; it has no effect",
        )


def check_labels(rules: Sequence[Rule], log: IssueLog) -> None:
    """Every GOTO needs a LABEL later in the file; every LABEL should be jumped to."""
    referenced: set[int] = set()
    for index, rule in enumerate(rules):
        gotos = rule.get("GOTO")
        if not gotos:
            continue
        target = gotos[0]
        later = next(
            (k for k in range(index + 1, len(rules)) if _last_label(rules[k]) == target.value),
            None,
        )
        if later is not None:
            referenced.add(later)
            continue
        earlier = any(_last_label(r) == target.value for r in rules[: index + 1])
        why = (
            "the LABEL comes before it; udev only jumps forward"
            if earlier
            else "no LABEL with that name follows in this file"
        )
        log.at(
            target,
            "error",
            Code.GOTO_WITHOUT_LABEL,
            f'GOTO="{target.value}" has no matching LABEL: {why}',
        )
    for index, rule in enumerate(rules):
        labels = rule.get("LABEL")
        if labels and index not in referenced:
            a = labels[-1]
            log.at(a, "warning", Code.UNUSED_LABEL, f'LABEL="{a.value}" is never jumped to')


def _last_label(rule: Rule) -> str | None:
    # udev keeps the last LABEL of a rule (Rule.label gives the first).
    labels = rule.get("LABEL")
    return labels[-1].value if labels else None
