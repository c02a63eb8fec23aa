"""A strict parser and validator for udev rules files: the entry points.

udev itself is lenient: ``udevadm`` 252 (no ``udevadm verify`` before systemd 253)
accepts a rule with a missing comma without a word, ignores keys it does not know
with a log line nobody reads, and silently changes some operators. This parser
follows systemd's own (``src/udev/udev-rules.c``: ``parse_line``,
``parse_token``, ``udev_check_format``) and turns each of those cases into an
:class:`~.model.Issue` with file, line, column and cause. It never touches the system.

The work is split into :mod:`.lexer` (text to pairs), :mod:`.checks` (what udev
would reject or misread) and the tables of :mod:`.keys`.

Used by the tests of the shipped rules and by ``spotlab udev check FILE``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spotlab.console.udev.checks import check_assignment, check_labels, check_rule
from spotlab.console.udev.lexer import WHITESPACE, logical_lines, split_pairs
from spotlab.console.udev.model import Assignment, Issue, IssueLog, Rule


@dataclass(frozen=True)
class RulesFile:
    """A parsed rules file: its rules and every issue found."""

    path: str
    rules: tuple[Rule, ...]
    issues: tuple[Issue, ...]

    @property
    def errors(self) -> list[Issue]:
        return [i for i in self.issues if i.severity == "error"]

    @property
    def warnings(self) -> list[Issue]:
        return [i for i in self.issues if i.severity == "warning"]

    @property
    def ok(self) -> bool:
        """True when there is no error (warnings allowed)."""
        return not self.errors

    def assignments(self) -> Iterator[Assignment]:
        for rule in self.rules:
            yield from rule.assignments

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "ok": self.ok,
            "rules": len(self.rules),
            "errors": len(self.errors),
            "warnings": len(self.warnings),
            "issues": [i.to_dict() for i in self.issues],
        }


class UdevRulesError(ValueError):
    """Raised by :func:`check_text` / :func:`check_file` when a file has errors."""

    def __init__(self, rules_file: RulesFile) -> None:
        self.rules_file = rules_file
        lines = [str(i) for i in rules_file.errors]
        super().__init__("\n".join(lines) if lines else f"{rules_file.path}: invalid")


def parse_rules(text: str, path: str = "<string>") -> RulesFile:
    """Parse rules text; never raises for bad content, the issues say what is wrong."""
    log = IssueLog(path)
    rules: list[Rule] = []
    for logical in logical_lines(text, log):
        before = len(log.issues)
        assignments = split_pairs(logical, log)
        for a in assignments:
            check_assignment(a, log)
        rule = Rule(
            line=assignments[0].line if assignments else logical.first_line,
            end_line=logical.last_line,
            text=logical.text.strip(WHITESPACE),
            assignments=tuple(assignments),
        )
        check_rule(rule, log.has_errors(since=before), log)
        rules.append(rule)
    check_labels(rules, log)
    issues = sorted(log.issues, key=lambda i: (i.line, i.column))
    return RulesFile(path, tuple(rules), tuple(issues))


def parse_file(path: str | os.PathLike[str]) -> RulesFile:
    """Parse a rules file (UTF-8)."""
    p = Path(path)
    return parse_rules(p.read_text(encoding="utf-8"), str(p))


def check_text(text: str, path: str = "<string>") -> RulesFile:
    """Parse and raise :class:`UdevRulesError` if there is any error."""
    return _raise_on_errors(parse_rules(text, path))


def check_file(path: str | os.PathLike[str]) -> RulesFile:
    """Parse a file and raise :class:`UdevRulesError` if there is any error."""
    return _raise_on_errors(parse_file(path))


def _raise_on_errors(result: RulesFile) -> RulesFile:
    if not result.ok:
        raise UdevRulesError(result)
    return result
