"""Text to pairs: logical lines, then ``KEY{attr}OP"value"`` pairs separated by commas.

Follows ``udev_rules_parse_file()`` and ``parse_line()`` of systemd's
``src/udev/udev-rules.c``: comments are skipped even inside a continuation,
a trailing backslash joins lines, values are always double-quoted, and an
``e`` prefix turns on C escapes. Where udev is lenient (a missing comma) this
reports an issue instead.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass

from spotlab.console.udev.keys import OPERATORS_LONGEST_FIRST, OPERATORS_SHOWN
from spotlab.console.udev.model import Assignment, Code, IssueLog, Severity

WHITESPACE = " \t\r\n"
_EXPECTED_OPERATOR = ", ".join(OPERATORS_SHOWN)
_C_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", "a": "\a", "b": "\b", "f": "\f", "v": "\v"}


@dataclass
class LogicalLine:
    """Physical lines joined at trailing backslashes, with where each piece came from."""

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


def logical_lines(text: str, log: IssueLog) -> Iterator[LogicalLine]:
    """The non-empty logical lines of ``text``; a dangling continuation goes to ``log``."""
    pending: LogicalLine | None = None
    last_line = 0
    for number, raw in enumerate(text.splitlines(), start=1):
        last_line = number
        stripped = raw.lstrip(WHITESPACE)
        lead = len(raw) - len(stripped)
        # Comments are skipped even inside a continuation.
        if stripped.startswith("#"):
            continue
        continued = stripped.endswith("\\")
        piece = stripped[:-1] if continued else stripped
        if pending is None:
            pending = LogicalLine("", [])
        pending.spans.append((len(pending.text), number, lead))
        pending.text += piece
        if continued:
            continue
        if pending.text.strip(WHITESPACE):
            yield pending
        pending = None
    if pending is not None:
        log.add(
            last_line,
            1,
            "error",
            Code.SYNTAX,
            "file ends with a line continuation ('\\'); udev ignores that rule",
        )


def split_pairs(logical: LogicalLine, log: IssueLog) -> list[Assignment]:
    """The pairs of one logical line; none if the line cannot be read to its end."""
    text = logical.text
    n = len(text)
    pos = 0
    first = True
    found: list[Assignment] = []
    local = IssueLog(log.path)

    def at(offset: int, severity: Severity, code: Code, message: str) -> None:
        line, col = logical.locate(offset)
        local.add(line, col, severity, code, message)

    failed = False
    while True:
        sep_start = pos
        commas = 0
        while pos < n and (text[pos] in WHITESPACE or text[pos] == ","):
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
            if c in WHITESPACE or c in "={":
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
        op = next((o for o in OPERATORS_LONGEST_FIRST if text.startswith(o, pos)), None)
        if op is None:
            found_text = text[pos : pos + 2] or "end of line"
            at(
                pos,
                "error",
                Code.BAD_OPERATOR,
                f"expected an operator ({_EXPECTED_OPERATOR}) after {key}, found '{found_text}'",
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
        value = _unescape(text[value_start:j], escaped)
        found.append(Assignment(key, attr, op, value, prefix, line, col))
        pos = j + 1
        first = False

    quotes = _unescaped_quotes(text)
    if local.has_errors() and quotes % 2:
        # A lost quote shifts every later pair; report the cause, not the echoes.
        first_error = next(i for i in local.issues if i.severity == "error")
        log.add(
            first_error.line,
            first_error.column,
            "error",
            Code.UNBALANCED_QUOTE,
            f"unbalanced double quotes ({quotes} in this rule): a quote is missing or extra",
        )
        return []
    log.issues.extend(local.issues)
    return [] if failed else found


def _unescape(raw: str, escaped: bool) -> str:
    if not escaped:
        return raw.replace('\\"', '"')
    out: list[str] = []
    i = 0
    while i < len(raw):
        c = raw[i]
        if c == "\\" and i + 1 < len(raw):
            nxt = raw[i + 1]
            out.append(_C_ESCAPES.get(nxt, nxt))
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
