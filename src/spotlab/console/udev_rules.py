"""A strict parser and validator for udev rules files.

udev itself is lenient: ``udevadm`` 252 (no ``udevadm verify`` before systemd 253)
accepts a rule with a missing comma without a word, ignores keys it does not know
with a log line nobody reads, and silently changes some operators. This module
follows systemd's own parser (``src/udev/udev-rules.c``: ``parse_line``,
``parse_token``, ``udev_check_format``) and turns each of those cases into an
:class:`Issue` with file, line, column and cause. It never touches the system.

Severities:

* ``error``: udev rejects the pair or the line, ignores it, or the rule cannot do
  what it says (unknown key, operator the key does not take, missing comma,
  unbalanced quote, GOTO without a LABEL after it, world-writable MODE, ...).
* ``warning``: udev accepts it but means something else (``MODE+=`` becomes
  ``MODE=``), or it is dead weight (unused LABEL, a rule with no effect).

Used by the tests of the shipped rules and by ``spotlab udev check FILE``.
"""

from __future__ import annotations

import difflib
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any, Literal

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


MATCH_OPERATORS = frozenset({"==", "!="})
ASSIGN_OPERATORS = frozenset({"=", "+=", "-=", ":="})
# Longest first; "=" last so that "==" wins.
_OPERATORS = ("==", "!=", "+=", "-=", ":=", "=")

_WHITESPACE = " \t\r\n"


@dataclass(frozen=True)
class KeySpec:
    """What udev accepts for one key.

    ``ops`` are taken as written; ``coerced`` are accepted by udev with a log
    warning and then treated as ``=``; any other operator makes udev drop the line.
    ``check_value`` says when the value is a format string (``%E{...}``, ``$attr{...}``)
    that udev checks: for assignments only, always, or never (match patterns).
    """

    attr: Literal["none", "required", "optional"]
    ops: frozenset[str]
    coerced: frozenset[str] = frozenset()
    attr_values: frozenset[str] | None = None
    check_value: Literal["never", "assign", "always"] = "never"
    nonempty: bool = False
    case_prefix: bool = True


def _ops(*ops: str) -> frozenset[str]:
    return frozenset(ops)


_M = MATCH_OPERATORS

#: Every key of udev(7) in systemd 252..258 and the operators each one takes.
KEYS: dict[str, KeySpec] = {
    # Match keys on the event device.
    "ACTION": KeySpec("none", _M),
    "DEVPATH": KeySpec("none", _M),
    "KERNEL": KeySpec("none", _M),
    "SUBSYSTEM": KeySpec("none", _M),
    "DRIVER": KeySpec("none", _M),
    "CONST": KeySpec("required", _M, attr_values=_ops("arch", "virt", "cvm")),
    "RESULT": KeySpec("none", _M),
    # Match keys on the device or any parent (all on the same parent).
    "KERNELS": KeySpec("none", _M),
    "SUBSYSTEMS": KeySpec("none", _M),
    "DRIVERS": KeySpec("none", _M),
    "ATTRS": KeySpec("required", _M),
    "TAGS": KeySpec("none", _M),
    "TEST": KeySpec("optional", _M, check_value="always", nonempty=True, case_prefix=False),
    # Keys that match with ==/!= and assign with the others.
    "SYMLINK": KeySpec("none", _M | ASSIGN_OPERATORS, check_value="assign"),
    "NAME": KeySpec("none", _M | _ops("=", ":="), coerced=_ops("+="), check_value="assign"),
    "ENV": KeySpec("required", _M | _ops("=", "+="), coerced=_ops(":="), check_value="assign"),
    "TAG": KeySpec(
        "none", _M | _ops("=", "+=", "-="), coerced=_ops(":="), check_value="assign", nonempty=True
    ),
    "ATTR": KeySpec("required", _M | _ops("="), coerced=_ops("+=", ":="), check_value="assign"),
    "SYSCTL": KeySpec("required", _M | _ops("="), coerced=_ops("+=", ":="), check_value="assign"),
    # Run something and match on its outcome (an assignment operator counts as "==").
    "PROGRAM": KeySpec(
        "none",
        _M | _ops("=", "+=", ":="),
        check_value="always",
        nonempty=True,
        case_prefix=False,
    ),
    "IMPORT": KeySpec(
        "required",
        _M | _ops("=", "+=", ":="),
        attr_values=_ops("file", "program", "builtin", "db", "cmdline", "parent"),
        check_value="always",
        nonempty=True,
        case_prefix=False,
    ),
    # Assignment-only keys.
    "OPTIONS": KeySpec("none", _ops("=", "+=", ":=")),
    "OWNER": KeySpec(
        "none", _ops("=", ":="), coerced=_ops("+="), check_value="assign", nonempty=True
    ),
    "GROUP": KeySpec(
        "none", _ops("=", ":="), coerced=_ops("+="), check_value="assign", nonempty=True
    ),
    "MODE": KeySpec(
        "none", _ops("=", ":="), coerced=_ops("+="), check_value="assign", nonempty=True
    ),
    "SECLABEL": KeySpec(
        "required", _ops("=", "+="), coerced=_ops(":="), check_value="assign", nonempty=True
    ),
    "RUN": KeySpec(
        "optional",
        _ops("=", "+=", ":="),
        attr_values=_ops("program", "builtin"),
        check_value="assign",
        nonempty=True,
    ),
    "GOTO": KeySpec("none", _ops("=")),
    "LABEL": KeySpec("none", _ops("=")),
}

#: Keys of old udev versions, with what replaced them.
LEGACY_KEYS: dict[str, str] = {
    "WAIT_FOR": 'removed in udev 217; use TEST{}=="..." or fix the driver',
    "WAIT_FOR_SYSFS": 'removed in udev 217; use TEST{}=="..."',
    "BUS": "removed in udev 098; use SUBSYSTEMS==",
    "SYSFS": "removed in udev 098; use ATTRS{}==",
    "ID": "removed in udev 098; use KERNELS==",
    "PLACE": "removed in udev 050; use KERNELS==",
    "IGNORE_DEVICE": "removed; use GOTO to skip the device",
}

#: udev built-in commands (IMPORT{builtin}, RUN{builtin}).
BUILTINS = frozenset(
    {
        "blkid",
        "btrfs",
        "dissect_image",
        "factory_reset",
        "hwdb",
        "input_id",
        "keyboard",
        "kmod",
        "net_driver",
        "net_id",
        "net_setup_link",
        "path_id",
        "uaccess",
        "usb_id",
    }
)

#: Device properties udev refuses to let rules set (device_property_can_set()).
READ_ONLY_PROPERTIES = frozenset(
    {
        "ACTION",
        "SEQNUM",
        "SYNTH_UUID",
        "DEVPATH",
        "DEVPATH_OLD",
        "SUBSYSTEM",
        "DEVTYPE",
        "DRIVER",
        "MODALIAS",
        "DEVNAME",
        "DEVMODE",
        "DEVUID",
        "DEVGID",
        "MAJOR",
        "MINOR",
        "DISKSEQ",
        "PARTN",
        "IFINDEX",
        "INTERFACE",
        "DEVLINKS",
        "TAGS",
        "CURRENT_TAGS",
        "USEC_INITIALIZED",
        "UDEV_DATABASE_VERSION",
    }
)

_LOG_LEVELS = frozenset(
    {"emerg", "alert", "crit", "err", "warning", "notice", "info", "debug", "reset"}
    | {str(n) for n in range(8)}
)

# Format substitutions of udev-format.c: long names ($name) in udev's order, short (%c).
_SUBST_LONG = (
    ("devnode", "N"),
    ("tempnode", "N"),
    ("attr", "s"),
    ("sysfs", "s"),
    ("env", "E"),
    ("kernel", "k"),
    ("number", "n"),
    ("driver", "d"),
    ("devpath", "p"),
    ("id", "b"),
    ("major", "M"),
    ("minor", "m"),
    ("result", "c"),
    ("parent", "P"),
    ("name", "D"),
    ("links", "L"),
    ("root", "r"),
    ("sys", "S"),
)
_SUBST_SHORT = frozenset(char for _, char in _SUBST_LONG)
_OCTAL_MODE = re.compile(r"[0-7]{1,4}")
_RESULT_INDEX = re.compile(r"[0-9]+\+?")


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


# --------------------------------------------------------------------------- helpers


def mode_bits(value: str) -> int | None:
    """The permission bits of a MODE value ("0660", "660"), or None if not octal."""
    if not _OCTAL_MODE.fullmatch(value):
        return None
    return int(value, 8)


def is_world_writable(value: str) -> bool:
    """True if a MODE value lets every user write (the "other" write bit, 0o002)."""
    bits = mode_bits(value)
    return bits is not None and bool(bits & 0o002)


def format_problem(value: str) -> tuple[int, str] | None:
    """Check udev substitutions (``%E{KEY}``, ``$attr{x}``, ``%%``, ``$$``) like udev_check_format.

    Returns (offset, hint) of the first invalid substitution, or None.
    """
    i = 0
    n = len(value)
    while i < n:
        char = value[i]
        if char not in "%$":
            i += 1
            continue
        nxt = value[i + 1 : i + 2]
        if nxt == char:
            i += 2
            continue
        kind = ""
        j = i + 1
        if char == "$":
            for name, short in _SUBST_LONG:
                if value.startswith(name, i + 1):
                    kind, j = short, i + 1 + len(name)
                    break
        elif nxt in _SUBST_SHORT and nxt:
            kind, j = nxt, i + 2
        if not kind:
            return (
                i,
                f"invalid substitution '{value[i : i + 2]}' "
                f"(write '{char}{char}' for a literal '{char}')",
            )
        attr = ""
        if value[j : j + 1] == "{":
            end = value.find("}", j + 1)
            if end < 0:
                return j, "'{' of the substitution is not closed"
            attr = value[j + 1 : end]
            if not attr:
                return j, "empty '{}' in substitution"
            j = end + 1
        if kind in ("s", "E") and not attr:
            return i, f"'{value[i:j]}' needs an attribute, e.g. %E{{ID_SERIAL_SHORT}}"
        if kind == "c" and attr and not _RESULT_INDEX.fullmatch(attr):
            return i, f"'{value[i:j]}': result index must be a number, optionally followed by '+'"
        i = j
    return None


def _unescape(raw: str, escaped: bool) -> str:
    if not escaped:
        return raw.replace('\\"', '"')
    table = {"n": "\n", "t": "\t", "r": "\r", "a": "\a", "b": "\b", "f": "\f", "v": "\v"}
    out: list[str] = []
    i = 0
    while i < len(raw):
        c = raw[i]
        if c == "\\" and i + 1 < len(raw):
            nxt = raw[i + 1]
            out.append(table.get(nxt, nxt))
            i += 2
            continue
        out.append(c)
        i += 1
    return "".join(out)


def _unescaped_quotes(text: str) -> int:
    count = 0
    for i, c in enumerate(text):
        if c == '"' and (i == 0 or text[i - 1] != "\\"):
            count += 1
    return count


# --------------------------------------------------------------------------- parsing


@dataclass
class _Logical:
    text: str
    # (offset in text, physical line, 0-based column of that offset in the line)
    spans: list[tuple[int, int, int]]

    def locate(self, offset: int) -> tuple[int, int]:
        """(line, 1-based column) of an offset in the joined text."""
        line, col0 = self.spans[0][1], self.spans[0][2]
        start = 0
        for span_start, span_line, span_col in self.spans:
            if span_start > offset:
                break
            start, line, col0 = span_start, span_line, span_col
        return line, col0 + (offset - start) + 1

    @property
    def first_line(self) -> int:
        return self.spans[0][1]

    @property
    def last_line(self) -> int:
        return self.spans[-1][1]


class _Parser:
    def __init__(self, path: str) -> None:
        self.path = path
        self.issues: list[Issue] = []

    def issue(self, line: int, column: int, severity: Severity, code: Code, message: str) -> None:
        self.issues.append(Issue(self.path, line, column, severity, code, message))

    # -- physical lines -> logical lines, as udev_rules_parse_file() does
    def logical_lines(self, text: str) -> Iterator[_Logical]:
        pending: _Logical | None = None
        last_line = 0
        for number, raw in enumerate(text.splitlines(), start=1):
            last_line = number
            stripped = raw.lstrip(_WHITESPACE)
            lead = len(raw) - len(stripped)
            # Comments are skipped even inside a continuation.
            if stripped.startswith("#"):
                continue
            continued = stripped.endswith("\\")
            piece = stripped[:-1] if continued else stripped
            if pending is None:
                pending = _Logical("", [])
            pending.spans.append((len(pending.text), number, lead))
            pending.text += piece
            if continued:
                continue
            if pending.text.strip(_WHITESPACE):
                yield pending
            pending = None
        if pending is not None:
            self.issue(
                last_line,
                1,
                "error",
                Code.SYNTAX,
                "file ends with a line continuation ('\\'); udev ignores that rule",
            )

    # -- one logical line -> assignments
    def tokenize(self, logical: _Logical) -> list[Assignment]:
        text = logical.text
        n = len(text)
        pos = 0
        first = True
        found: list[Assignment] = []
        local: list[Issue] = []

        def at(offset: int, severity: Severity, code: Code, message: str) -> None:
            line, col = logical.locate(offset)
            local.append(Issue(self.path, line, col, severity, code, message))

        failed = False
        while True:
            sep_start = pos
            commas = 0
            while pos < n and (text[pos] in _WHITESPACE or text[pos] == ","):
                commas += text[pos] == ","
                pos += 1
            if pos >= n:
                if commas and not first:
                    at(sep_start, "warning", Code.EXTRA_COMMA, "stray comma at the end of the rule")
                break
            if first and commas:
                at(sep_start, "warning", Code.EXTRA_COMMA, "stray comma at the start of the rule")
            elif not first and commas == 0:
                word = re.match(r"[^\s,=!+\-:{]*", text[pos:])
                shown = word.group(0) if word and word.group(0) else text[pos : pos + 10]
                at(
                    pos,
                    "error",
                    Code.MISSING_COMMA,
                    f"missing comma before '{shown}': pairs must be separated by ',' "
                    "(udev 252 accepts this silently)",
                )
            elif commas > 1:
                at(sep_start, "warning", Code.EXTRA_COMMA, "more than one comma between pairs")

            key_start = pos
            while pos < n:
                c = text[pos]
                if c in _WHITESPACE or c in "={":
                    break
                if c in "+-!:" and text[pos + 1 : pos + 2] == "=":
                    break
                pos += 1
            key = text[key_start:pos]
            if pos >= n:
                at(key_start, "error", Code.SYNTAX, f"'{key}' is not a KEY=\"value\" pair")
                failed = True
                break
            attr: str | None = None
            if text[pos] == "{":
                close = text.find("}", pos + 1)
                if close < 0:
                    at(pos, "error", Code.SYNTAX, f"'{{' after {key} is not closed by '}}'")
                    failed = True
                    break
                attr = text[pos + 1 : close]
                pos = close + 1
            while pos < n and text[pos] in " \t":
                pos += 1
            op = next((o for o in _OPERATORS if text.startswith(o, pos)), None)
            if op is None:
                found_text = text[pos : pos + 2] or "end of line"
                at(
                    pos,
                    "error",
                    Code.BAD_OPERATOR,
                    f"expected an operator (==, !=, =, +=, -=, :=) after {key}, "
                    f"found '{found_text}'",
                )
                failed = True
                break
            pos += len(op)
            while pos < n and text[pos] in " \t":
                pos += 1
            prefix = ""
            while pos < n and text[pos] in "ei" and text[pos] not in prefix and len(prefix) < 2:
                prefix += text[pos]
                pos += 1
            if pos >= n or text[pos] != '"':
                at(
                    pos,
                    "error",
                    Code.SYNTAX,
                    f'value of {key} must be in double quotes: {key}{op}"..."',
                )
                failed = True
                break
            value_start = pos + 1
            j = value_start
            escaped = "e" in prefix
            while j < n and text[j] != '"':
                if text[j] == "\\" and (escaped or text[j + 1 : j + 2] == '"'):
                    j += 1
                j += 1
            if j >= n:
                at(pos, "error", Code.UNBALANCED_QUOTE, f"value of {key} has no closing quote")
                failed = True
                break
            line, col = logical.locate(key_start)
            found.append(
                Assignment(
                    key=key,
                    attr=attr,
                    op=op,
                    value=_unescape(text[value_start:j], escaped),
                    prefix=prefix,
                    line=line,
                    column=col,
                )
            )
            pos = j + 1
            first = False

        has_errors = any(i.severity == "error" for i in local)
        quotes = _unescaped_quotes(text)
        if has_errors and quotes % 2:
            # A lost quote shifts every later pair; report the cause, not the echoes.
            first_error = next(i for i in local if i.severity == "error")
            self.issue(
                first_error.line,
                first_error.column,
                "error",
                Code.UNBALANCED_QUOTE,
                f"unbalanced double quotes ({quotes} in this rule): a quote is missing or extra",
            )
            return []
        self.issues.extend(local)
        return [] if failed else found

    # -- per pair
    def check_assignment(self, a: Assignment) -> None:
        def err(code: Code, message: str) -> None:
            self.issue(a.line, a.column, "error", code, message)

        def warn(code: Code, message: str) -> None:
            self.issue(a.line, a.column, "warning", code, message)

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
                    f"{a.key} does not take '{a.op}'; udev treats it as '=' ({_takes(spec)})",
                )
            elif spec.ops <= MATCH_OPERATORS:
                err(
                    Code.BAD_OPERATOR,
                    f"{a.key} is a match key and takes '==' or '!=', not '{a.op}'",
                )
            else:
                err(Code.BAD_OPERATOR, f"{a.key} does not take '{a.op}' ({_takes(spec)})")

        # prefixes
        if "i" in a.prefix:
            if a.op not in MATCH_OPERATORS:
                err(
                    Code.BAD_PREFIX,
                    f"prefix 'i' (case-insensitive) needs '==' or '!=', not '{a.op}'",
                )
            elif not spec.case_prefix:
                err(Code.BAD_PREFIX, f"{a.key} does not take the prefix 'i'")

        # value
        assigning = a.op not in MATCH_OPERATORS
        checked = spec.check_value == "always" or (spec.check_value == "assign" and assigning)
        if spec.nonempty and (assigning or spec.check_value == "always") and not a.value:
            warn(Code.BAD_VALUE, f"{a.key} has an empty value")
        elif checked:
            problem = format_problem(a.value)
            if problem:
                err(Code.BAD_VALUE, f'{a.key}="{a.value}": {problem[1]}')

        if a.key == "MODE" and assigning:
            self.check_mode(a)
        elif a.key == "OPTIONS":
            self.check_options(a)
        elif a.key == "ENV" and assigning and a.attr in READ_ONLY_PROPERTIES:
            err(
                Code.BAD_ATTRIBUTE,
                f"ENV{{{a.attr}}} is set by the kernel or udev and cannot be assigned",
            )
        elif a.key == "NAME" and assigning and a.value in ("", "%k"):
            err(Code.BAD_VALUE, f'NAME="{a.value}" has no effect; udev ignores it')
        elif a.key == "SUBSYSTEM" and a.value in ("bus", "class"):
            warn(Code.BAD_VALUE, f'SUBSYSTEM=="{a.value}" should be written "subsystem"')
        elif (a.key == "IMPORT" and a.attr == "builtin") or (
            a.key == "RUN" and a.attr == "builtin"
        ):
            command = a.value.split(maxsplit=1)[0] if a.value.strip() else ""
            if command not in BUILTINS:
                err(Code.BAD_VALUE, f"unknown udev builtin '{command}'")

    def check_mode(self, a: Assignment) -> None:
        bits = mode_bits(a.value)
        if bits is None:
            self.issue(
                a.line,
                a.column,
                "error",
                Code.BAD_VALUE,
                f'MODE="{a.value}" is not an octal mode such as "0660"',
            )
            return
        if bits & 0o002:
            self.issue(
                a.line,
                a.column,
                "error",
                Code.WORLD_WRITABLE,
                f'MODE="{a.value}" makes the device writable by every user; use TAG+="uaccess" '
                'or MODE="0660" with GROUP=',
            )
        if bits & 0o7000:
            self.issue(
                a.line,
                a.column,
                "warning",
                Code.BAD_VALUE,
                f'MODE="{a.value}" sets setuid/setgid/sticky bits, '
                "which mean nothing on a device node",
            )

    def check_options(self, a: Assignment) -> None:
        value = a.value
        ok = value in ("dump", "string_escape=none", "string_escape=replace", "db_persist")
        ok = ok or value in ("watch", "nowatch")
        if value.startswith("static_node="):
            ok = bool(value.removeprefix("static_node="))
        elif value.startswith("link_priority="):
            ok = re.fullmatch(r"[+-]?[0-9]+", value.removeprefix("link_priority=")) is not None
        elif value.startswith("log_level="):
            ok = value.removeprefix("log_level=") in _LOG_LEVELS
        if not ok:
            self.issue(
                a.line,
                a.column,
                "error",
                Code.BAD_VALUE,
                f'OPTIONS="{value}" is not a udev option; udev ignores it '
                "(one option per OPTIONS key)",
            )

    # -- per rule
    def check_rule(self, rule: Rule, had_errors: bool) -> None:
        gotos = rule.get("GOTO")
        labels = rule.get("LABEL")
        if len(gotos) > 1:
            a = gotos[1]
            self.issue(
                a.line,
                a.column,
                "warning",
                Code.MULTIPLE_GOTO,
                "more than one GOTO; udev uses the first",
            )
        if len(labels) > 1:
            a = labels[1]
            self.issue(
                a.line,
                a.column,
                "warning",
                Code.MULTIPLE_LABEL,
                "more than one LABEL; udev uses the last",
            )
        if had_errors or not rule.assignments:
            return
        effect = any(
            (not a.is_match and a.key in KEYS) or a.key in ("PROGRAM", "IMPORT")
            for a in rule.assignments
        )
        if not effect:
            first = rule.assignments[0]
            self.issue(
                first.line,
                first.column,
                "warning",
                Code.NO_EFFECT,
                "rule only matches and assigns nothing; it has no effect",
            )

    # -- whole file
    def check_labels(self, rules: list[Rule]) -> None:
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
            self.issue(
                target.line,
                target.column,
                "error",
                Code.GOTO_WITHOUT_LABEL,
                f'GOTO="{target.value}" has no matching LABEL: {why}',
            )
        for index, rule in enumerate(rules):
            labels = rule.get("LABEL")
            if labels and index not in referenced:
                a = labels[-1]
                self.issue(
                    a.line,
                    a.column,
                    "warning",
                    Code.UNUSED_LABEL,
                    f'LABEL="{a.value}" is never jumped to',
                )

    def parse(self, text: str) -> RulesFile:
        rules: list[Rule] = []
        for logical in self.logical_lines(text):
            before = len(self.issues)
            assignments = self.tokenize(logical)
            for a in assignments:
                self.check_assignment(a)
            had_errors = any(i.severity == "error" for i in self.issues[before:])
            rule = Rule(
                line=assignments[0].line if assignments else logical.first_line,
                end_line=logical.last_line,
                text=logical.text.strip(_WHITESPACE),
                assignments=tuple(assignments),
            )
            self.check_rule(rule, had_errors)
            rules.append(rule)
        self.check_labels(rules)
        issues = sorted(self.issues, key=lambda i: (i.line, i.column))
        return RulesFile(self.path, tuple(rules), tuple(issues))


def _last_label(rule: Rule) -> str | None:
    labels = rule.get("LABEL")
    return labels[-1].value if labels else None


def _takes(spec: KeySpec) -> str:
    order = [o for o in ("==", "!=", "=", "+=", "-=", ":=") if o in spec.ops]
    return "takes " + ", ".join(f"'{o}'" for o in order)


# --------------------------------------------------------------------------- public API


def parse_rules(text: str, path: str = "<string>") -> RulesFile:
    """Parse rules text; never raises for bad content, the issues say what is wrong."""
    return _Parser(path).parse(text)


def parse_file(path: str | os.PathLike[str]) -> RulesFile:
    """Parse a rules file (UTF-8)."""
    p = Path(path)
    return parse_rules(p.read_text(encoding="utf-8"), str(p))


def check_text(text: str, path: str = "<string>") -> RulesFile:
    """Parse and raise :class:`UdevRulesError` if there is any error."""
    result = parse_rules(text, path)
    if not result.ok:
        raise UdevRulesError(result)
    return result


def check_file(path: str | os.PathLike[str]) -> RulesFile:
    """Parse a file and raise :class:`UdevRulesError` if there is any error."""
    result = parse_file(path)
    if not result.ok:
        raise UdevRulesError(result)
    return result
