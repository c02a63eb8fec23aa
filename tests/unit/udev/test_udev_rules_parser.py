"""spotlab.console.udev.rules: the strict udev rules parser, one test per error class."""

from __future__ import annotations

from pathlib import Path

import pytest

from spotlab.console.udev import (
    KEYS,
    Code,
    UdevRulesError,
    check_text,
    format_problem,
    is_world_writable,
    parse_file,
    parse_rules,
)

GOOD = 'ATTRS{idVendor}=="0403", ATTRS{idProduct}=="6001", TAG+="uaccess"\n'


def codes(text: str) -> list[str]:
    return [str(i.code) for i in parse_rules(text, "t.rules").issues]


def errors(text: str) -> list[str]:
    return [str(i.code) for i in parse_rules(text, "t.rules").errors]


def test_good_rule_splits_into_pairs() -> None:
    result = parse_rules(GOOD, "t.rules")
    assert result.ok and result.issues == ()
    (rule,) = result.rules
    assert [(a.key, a.attr, a.op, a.value) for a in rule.assignments] == [
        ("ATTRS", "idVendor", "==", "0403"),
        ("ATTRS", "idProduct", "==", "6001"),
        ("TAG", None, "+=", "uaccess"),
    ]
    assert [a.column for a in rule.assignments] == [1, 26, 52]


def test_comments_blank_lines_and_continuations() -> None:
    text = (
        "# comment\n"
        "\n"
        'KERNEL=="ttyUSB*", \\\n'
        "# comments inside a continuation are skipped, as udev does\n"
        '    MODE="0660", \\\n'
        '    GROUP="dialout"\n'
    )
    result = parse_rules(text, "t.rules")
    assert result.issues == ()
    (rule,) = result.rules
    assert (rule.line, rule.end_line) == (3, 6)
    assert [(a.key, a.line, a.column) for a in rule.assignments] == [
        ("KERNEL", 3, 1),
        ("MODE", 5, 5),
        ("GROUP", 6, 5),
    ]


def test_escapes_and_prefixes() -> None:
    text = 'ATTRS{product}==i"oak*", PROGRAM="/bin/echo \\"x\\"", ENV{A}=e"a\\tb"\n'
    result = parse_rules(text, "t.rules")
    assert result.issues == ()
    values = [(a.prefix, a.value) for a in result.rules[0].assignments]
    assert values == [("i", "oak*"), ("", '/bin/echo "x"'), ("e", "a\tb")]


# ----------------------------------------------------------------------------- unknown key


@pytest.mark.parametrize(
    ("text", "hint"),
    [
        ('FOO=="x", MODE="0660"\n', "unknown key 'FOO'"),
        ('subsystem=="usb", MODE="0660"\n', "did you mean 'SUBSYSTEM'"),
        ('ATTRIBUTE{x}=="1", MODE="0660"\n', "unknown key 'ATTRIBUTE'"),
        ('KERNEL=="x", WAIT_FOR="y"\n', "removed in udev 217"),
        ('BUS=="usb", MODE="0660"\n', "SUBSYSTEMS"),
    ],
)
def test_unknown_key(text: str, hint: str) -> None:
    result = parse_rules(text, "t.rules")
    (issue,) = result.errors
    assert issue.code is Code.UNKNOWN_KEY
    assert hint in issue.message


def test_every_documented_key_is_known() -> None:
    documented = """ACTION DEVPATH KERNEL NAME SYMLINK SUBSYSTEM DRIVER ATTR SYSCTL KERNELS
    SUBSYSTEMS DRIVERS ATTRS TAGS TAG ENV CONST TEST PROGRAM RESULT OWNER GROUP MODE SECLABEL
    RUN LABEL GOTO IMPORT OPTIONS""".split()
    assert set(documented) == set(KEYS)


# ----------------------------------------------------------------------------- bad operator


@pytest.mark.parametrize(
    "text",
    [
        'ATTRS{idVendor}="0403", MODE="0660"\n',  # match-only key assigned
        'SUBSYSTEM="usb", MODE="0660"\n',
        'KERNEL+="x", MODE="0660"\n',
        'KERNEL=="x", MODE=="0660"\n',  # assignment-only key matched
        'KERNEL=="x", GROUP!="plugdev"\n',
        'KERNEL=="x", RUN=="/bin/true"\n',
        'KERNEL=="x", ENV{A}-="1"\n',
        'KERNEL=="x", GOTO+="end"\nLABEL="end"\n',
        'KERNEL "x", MODE="0660"\n',  # no operator at all
    ],
)
def test_bad_operator(text: str) -> None:
    assert Code.BAD_OPERATOR in errors(text)


def test_attrs_assignment_message_names_the_match_operators() -> None:
    (issue,) = parse_rules('ATTRS{idVendor}="0403", MODE="0660"\n', "x.rules").errors
    assert str(issue) == (
        "x.rules:1:1: error: ATTRS is a match key and takes '==' or '!=', not '=' [bad-operator]"
    )


def test_operator_udev_silently_changes_is_a_warning() -> None:
    result = parse_rules('KERNEL=="x", MODE+="0660"\n', "t.rules")
    assert result.ok
    assert [str(i.code) for i in result.warnings] == [Code.BAD_OPERATOR]
    assert "treats it as '='" in result.warnings[0].message


# ----------------------------------------------------------------------------- missing comma


@pytest.mark.parametrize(
    ("text", "column"),
    [
        ('ATTRS{idVendor}=="0403" ATTRS{idProduct}=="6001", MODE="0660"\n', 25),
        ('ATTRS{idVendor}=="0403", ATTRS{idProduct}=="6001"MODE="0660"\n', 50),
        ('KERNEL=="x",\tMODE="0660"  GROUP="dialout"\n', 27),
    ],
)
def test_missing_comma(text: str, column: int) -> None:
    result = parse_rules(text, "t.rules")
    (issue,) = result.errors
    assert issue.code is Code.MISSING_COMMA
    assert (issue.line, issue.column) == (1, column)


def test_missing_comma_on_a_continuation_line_points_at_that_line() -> None:
    text = 'KERNEL=="x", \\\n  MODE="0660" GROUP="dialout"\n'
    (issue,) = parse_rules(text, "t.rules").errors
    assert (issue.code, issue.line, issue.column) == (Code.MISSING_COMMA, 2, 15)


def test_extra_commas_are_warnings() -> None:
    assert codes('KERNEL=="x",, MODE="0660"\n') == [Code.EXTRA_COMMA]
    assert codes('KERNEL=="x", MODE="0660",\n') == [Code.EXTRA_COMMA]


# ----------------------------------------------------------------------------- unbalanced quote


@pytest.mark.parametrize(
    "text",
    [
        'ATTRS{idVendor}=="0403, MODE="0660"\n',
        'ATTRS{idVendor}=="0403", MODE="0660\n',
        'ATTRS{idVendor}==0403", MODE="0660"\n',
        'KERNEL=="x", MODE="0660""\n',
    ],
)
def test_unbalanced_quote(text: str) -> None:
    result = parse_rules(text, "t.rules")
    assert [str(i.code) for i in result.errors] == [Code.UNBALANCED_QUOTE]


def test_unquoted_value() -> None:
    (issue,) = parse_rules('KERNEL==ttyUSB0, MODE="0660"\n', "t.rules").errors
    assert issue.code is Code.SYNTAX
    assert "double quotes" in issue.message


# ----------------------------------------------------------------------------- MODE


@pytest.mark.parametrize("mode", ["0666", "666", "0667", "0777", "0662", "0002", "1777"])
def test_world_writable_mode_is_an_error(mode: str) -> None:
    text = f'SUBSYSTEM=="usb", ATTRS{{idVendor}}=="03e7", MODE="{mode}"\n'
    assert Code.WORLD_WRITABLE in errors(text)
    assert is_world_writable(mode)


@pytest.mark.parametrize("mode", ["0660", "660", "0640", "0600", "0664"])
def test_group_modes_are_fine(mode: str) -> None:
    assert codes(f'KERNEL=="x", MODE="{mode}", GROUP="plugdev"\n') == []
    assert not is_world_writable(mode)


def test_non_octal_mode() -> None:
    assert errors('KERNEL=="x", MODE="rw-rw-rw-"\n') == [Code.BAD_VALUE]


def test_luxonis_rule_is_rejected() -> None:
    # The upstream 80-movidius.rules line; spotlab must never ship it.
    with pytest.raises(UdevRulesError, match="world-writable-mode"):
        check_text('SUBSYSTEM=="usb", ATTRS{idVendor}=="03e7", MODE="0666"\n', "80-movidius.rules")


# ----------------------------------------------------------------------------- GOTO / LABEL


def test_goto_without_label() -> None:
    result = parse_rules('ACTION!="add", GOTO="x_end"\nKERNEL=="x", MODE="0660"\n', "t.rules")
    (issue,) = result.errors
    assert (issue.code, issue.line) == (Code.GOTO_WITHOUT_LABEL, 1)
    assert 'GOTO="x_end"' in issue.message


def test_goto_to_an_earlier_label_is_an_error() -> None:
    text = 'LABEL="top"\nKERNEL=="x", GOTO="top"\n'
    assert Code.GOTO_WITHOUT_LABEL in errors(text)
    assert "only jumps forward" in parse_rules(text).errors[0].message


def test_goto_with_label_and_unused_label() -> None:
    text = 'ACTION!="add", GOTO="end"\nKERNEL=="x", MODE="0660"\nLABEL="end"\nLABEL="spare"\n'
    assert codes(text) == [Code.UNUSED_LABEL]


# ----------------------------------------------------------------------------- other checks


@pytest.mark.parametrize(
    ("text", "code"),
    [
        ('ATTRS=="x", MODE="0660"\n', Code.BAD_ATTRIBUTE),
        ('KERNEL{x}=="y", MODE="0660"\n', Code.BAD_ATTRIBUTE),
        ('CONST{os}=="linux", MODE="0660"\n', Code.BAD_ATTRIBUTE),
        ('KERNEL=="x", ENV{DEVNAME}="y"\n', Code.BAD_ATTRIBUTE),
        ('KERNEL=="x", IMPORT{builtin}="usbid"\n', Code.BAD_VALUE),
        ('KERNEL=="x", OPTIONS+="last_rule"\n', Code.BAD_VALUE),
        ('KERNEL=="x", SYMLINK+="spotlab/%E"\n', Code.BAD_VALUE),
        ('KERNEL=="x", SYMLINK+="spotlab/%q"\n', Code.BAD_VALUE),
        ('KERNEL=="x", MODE=i"0660"\n', Code.BAD_PREFIX),
        ('KERNEL=="x", \\\n', Code.SYNTAX),
        ('KERNEL=="x", MODE="0660", ATTR{x\n', Code.SYNTAX),
    ],
)
def test_other_errors(text: str, code: Code) -> None:
    assert code in errors(text)


def test_rule_without_effect_is_a_warning() -> None:
    assert codes('KERNEL=="x"\n') == [Code.NO_EFFECT]


def test_format_problem() -> None:
    assert format_problem("spotlab/%E{ID_SERIAL_SHORT}-if$env{ID_USB_INTERFACE_NUM}") is None
    assert format_problem("100%% $$ %k %n $kernel %c{2+}") is None
    assert format_problem("%E") is not None
    assert format_problem("$foo") is not None
    assert format_problem("%E{x") is not None
    assert format_problem("%c{x}") is not None


def test_check_text_raises_with_file_line_and_cause() -> None:
    with pytest.raises(UdevRulesError) as caught:
        check_text('KERNEL=="x", FOO="1"\n', "99-x.rules")
    assert str(caught.value) == "99-x.rules:1:14: error: unknown key 'FOO' [unknown-key]"
    assert check_text(GOOD).ok


def test_parse_file_reports_its_path(tmp_path: Path) -> None:
    path = tmp_path / "70-x.rules"
    path.write_text('KERNEL=="x" MODE="0660"\n')
    (issue,) = parse_file(path).errors
    assert str(issue).startswith(f"{path}:1:13: error: missing comma")


def test_issue_and_file_to_dict_are_json_ready() -> None:
    result = parse_rules('KERNEL=="x", MODE="0666"\n', "t.rules")
    data = result.to_dict()
    assert data["ok"] is False
    assert data["issues"][0]["code"] == "world-writable-mode"
    assert data["issues"][0]["line"] == 1
