"""The rules files in udev/ parse clean, grant no world access and do what docs/udev.md says."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from spotlab.console import udev
from spotlab.console.udev import RulesFile, is_world_writable, parse_file

ROOT = Path(__file__).resolve().parents[3]
UDEV_DIR = ROOT / "udev"
SHIPPED = sorted(UDEV_DIR.glob("*.rules"))


def _parsed(path: Path) -> RulesFile:
    return parse_file(path)


def test_the_expected_files_are_shipped() -> None:
    names = {p.name for p in SHIPPED}
    assert names == {udev.CLASSIFY_FILE, *udev.POLICIES.values()}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_file_parses_without_any_issue(path: Path) -> None:
    result = _parsed(path)
    assert result.rules, f"{path.name} has no rules"
    assert [str(i) for i in result.issues] == []


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_no_world_writable_mode_and_no_0666(path: Path) -> None:
    for a in _parsed(path).assignments():
        if a.key == "MODE":
            assert not is_world_writable(a.value), f"{path.name}:{a.line}: MODE={a.value}"
    # Also textually, so a MODE the parser would not reach cannot hide.
    assert not re.search(r"MODE\s*:?\+?=\s*\"0?6[0-7][2367]\"", path.read_text())


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_goto_has_a_label_after_it(path: Path) -> None:
    rules = _parsed(path).rules
    for index, rule in enumerate(rules):
        if rule.goto is None:
            continue
        later = [r.label for r in rules[index + 1 :]]
        assert rule.goto in later, f"{path.name}:{rule.line}: GOTO={rule.goto}"


def test_policy_files_sort_before_71_seat_rules() -> None:
    for name in udev.POLICIES.values():
        assert name < "71-seat.rules"
        assert udev.CLASSIFY_FILE < name


def _classify() -> RulesFile:
    return _parsed(UDEV_DIR / udev.CLASSIFY_FILE)


def test_classify_file_starts_with_openocd_style_guards() -> None:
    first, second = _classify().rules[:2]
    assert [str(a) for a in first.assignments] == ['ACTION!="add|change"', 'GOTO="spotlab_end"']
    assert [str(a) for a in second.assignments] == [
        'SUBSYSTEM!="usb|tty|usb-serial"',
        'GOTO="spotlab_end"',
    ]
    assert _classify().rules[-1].label == "spotlab_end"


@pytest.mark.parametrize(
    ("vid", "pid"),
    [
        ("0403", "6001"),
        ("0403", "6010"),
        ("0403", "6011"),
        ("0403", "6014"),
        ("0403", "6015"),
        ("067b", "2303"),
        ("10c4", "ea60"),
        ("1a86", "7523"),
        ("1209", "0001"),
        ("03e7", None),
        ("05c6", "901d"),
    ],
)
def test_each_adapter_is_tagged_and_hidden_from_modemmanager(vid: str, pid: str | None) -> None:
    for rule in _classify().rules:
        vendors = [a.value for a in rule.get("ATTRS") if a.attr == "idVendor"]
        if vendors != [vid]:
            continue
        products = [a.value.split("|") for a in rule.get("ATTRS") if a.attr == "idProduct"]
        if pid is None:
            assert products == [], "OAK: every product id of 03e7"
        elif not products or pid not in products[0]:
            continue
        env = {a.attr: a.value for a in rule.get("ENV") if not a.is_match}
        assert env == {"ID_SPOTLAB": "1", "ID_MM_DEVICE_IGNORE": "1"}
        return
    pytest.fail(f"no rule tags {vid}:{pid}")


def test_qualcomm_is_tagged_only_for_the_oak4() -> None:
    # Vendor 05c6 is Qualcomm's: phones and modems must not be tagged with the OAK4.
    for rule in _classify().rules:
        vendors = [a.value for a in rule.get("ATTRS") if a.attr == "idVendor"]
        if vendors == ["05c6"]:
            products = [a.value for a in rule.get("ATTRS") if a.attr == "idProduct"]
            assert products == ["901d"]
            assert ("SUBSYSTEM", "usb") in {(a.key, a.value) for a in rule.assignments}


def test_ftdi_latency_timer_is_1ms() -> None:
    for rule in _classify().rules:
        matches = {(a.key, a.value) for a in rule.assignments if a.is_match}
        if {("SUBSYSTEM", "usb-serial"), ("DRIVER", "ftdi_sio")} <= matches:
            assigned = [a for a in rule.get("ATTR") if a.attr == "latency_timer"]
            assert [(a.op, a.value) for a in assigned] == [("=", "1")]
            return
    pytest.fail("no latency_timer rule")


def test_stable_link_by_serial_number() -> None:
    links = [a.value for r in _classify().rules for a in r.get("SYMLINK") if a.op == "+="]
    assert "spotlab/%E{ID_SERIAL_SHORT}" in links
    for rule in _classify().rules:
        if rule.get("SYMLINK"):
            # Only when there is a serial number, else the link would be "spotlab/".
            assert ("ID_SERIAL_SHORT", "?*") in {(a.attr, a.value) for a in rule.get("ENV")}


def test_uaccess_policy_only_tags() -> None:
    result = _parsed(UDEV_DIR / udev.POLICIES["uaccess"])
    assigned = [str(a) for a in result.assignments() if not a.is_match]
    assert assigned == ['TAG+="uaccess"']
    assert all(a.key != "MODE" for a in result.assignments())


def test_plugdev_policy_is_0660_plugdev_on_usb_device_nodes() -> None:
    result = _parsed(UDEV_DIR / udev.POLICIES["plugdev"])
    (rule,) = result.rules
    assert [str(a) for a in rule.assignments if not a.is_match] == [
        'MODE="0660"',
        'GROUP="plugdev"',
    ]
    assert 'ENV{ID_SPOTLAB}=="1"' in [str(a) for a in rule.assignments]
