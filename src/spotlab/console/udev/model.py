"""The pieces of a parsed rules file: pairs, rules, and the issues found in them.

Severities:

* ``error``: udev rejects the pair or the line, ignores it, or the rule cannot do
  what it says (unknown key, operator the key does not take, missing comma,
  unbalanced quote, GOTO without a LABEL after it, world-writable MODE, ...).
* ``warning``: udev accepts it but means something else (``MODE+=`` becomes
  ``MODE=``), or it is dead weight (unused LABEL, a rule with no effect).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any, Literal

from spotlab.console.udev.keys import MATCH_OPERATORS

Severity = Literal["error", "warning"]


class Code(StrEnum):
    """What an :class:`Issue` is about (stable names, used in JSON output and tests)."""

    SYNTAX = "syntax"
    UNKNOWN_KEY = "unknown-key"
    BAD_OPERATOR = "bad-operator"
    BAD_ATTRIBUTE = "bad-attribute"
    BAD_PREFIX = "bad-prefix"
    BAD_VALUE = "bad-value"
    MISSING_COMMA = "missing-comma"
    EXTRA_COMMA = "extra-comma"
    UNBALANCED_QUOTE = "unbalanced-quote"
    WORLD_WRITABLE = "world-writable-mode"
    GOTO_WITHOUT_LABEL = "goto-without-label"
    MULTIPLE_GOTO = "multiple-goto"
    MULTIPLE_LABEL = "multiple-label"
    UNUSED_LABEL = "unused-label"
    NO_EFFECT = "no-effect"


@dataclass(frozen=True)
class Issue:
    """One problem found in a rules file."""

    path: str
    line: int
    column: int
    severity: Severity
    code: Code
    message: str

    def __str__(self) -> str:
        return (
            f"{self.path}:{self.line}:{self.column}: {self.severity}: {self.message} [{self.code}]"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "line": self.line,
            "column": self.column,
            "severity": self.severity,
            "code": str(self.code),
            "message": self.message,
        }


@dataclass(frozen=True)
class Assignment:
    """One ``KEY{attr}OP"value"`` pair.

    ``value`` is unescaped; ``prefix`` is "", "e" (C escapes), "i" (case-insensitive) or both.
    """

    key: str
    attr: str | None
    op: str
    value: str
    prefix: str
    line: int
    column: int

    @property
    def is_match(self) -> bool:
        return self.op in MATCH_OPERATORS

    def __str__(self) -> str:
        attr = "" if self.attr is None else "{" + self.attr + "}"
        value = self.value.replace('"', '\\"')
        return f'{self.key}{attr}{self.op}{self.prefix}"{value}"'


@dataclass(frozen=True)
class Rule:
    """One logical line (physical lines joined at a trailing backslash)."""

    line: int
    end_line: int
    text: str
    assignments: tuple[Assignment, ...]

    def get(self, key: str) -> list[Assignment]:
        """The pairs of this rule with the given key, in order."""
        return [a for a in self.assignments if a.key == key]

    @property
    def label(self) -> str | None:
        labels = self.get("LABEL")
        return labels[0].value if labels else None

    @property
    def goto(self) -> str | None:
        gotos = self.get("GOTO")
        return gotos[0].value if gotos else None


class IssueLog:
    """The issues of one file, in the order they were found (the parser's notebook)."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.issues: list[Issue] = []

    def add(self, line: int, column: int, severity: Severity, code: Code, message: str) -> None:
        self.issues.append(Issue(self.path, line, column, severity, code, message))

    def at(self, a: Assignment, severity: Severity, code: Code, message: str) -> None:
        """An issue located at the start of a pair."""
        self.add(a.line, a.column, severity, code, message)

    def has_errors(self, since: int = 0) -> bool:
        """True if an error was logged at or after index ``since``."""
        return any(i.severity == "error" for i in self.issues[since:])
