"""The WSX hub's VID:PID (docs/protocols/wsx.md §2) is tagged, and the policies grant
access to its USB device node without a world-writable mode."""

from __future__ import annotations

from pathlib import Path

from spotlab.console import udev
from spotlab.console.udev import is_world_writable, parse_file
from spotlab.drivers.wsx import PRODUCT_ID, VENDOR_ID
from spotlab.drivers.wsx.usbio import UDEV_HINT

UDEV_DIR = Path(__file__).resolve().parents[3] / "udev"


def test_the_wsx_hub_is_tagged_on_the_usb_subsystem() -> None:
    vid, pid = f"{VENDOR_ID:04x}", f"{PRODUCT_ID:04x}"
    for rule in parse_file(UDEV_DIR / udev.CLASSIFY_FILE).rules:
        attrs = {a.attr: a.value for a in rule.get("ATTRS")}
        if attrs.get("idVendor") == vid and pid in attrs.get("idProduct", "").split("|"):
            env = {a.attr: a.value for a in rule.get("ENV") if not a.is_match}
            assert env == {"ID_SPOTLAB": "1", "ID_MM_DEVICE_IGNORE": "1"}
            assert [a.value for a in rule.get("SUBSYSTEM")] == ["usb"]
            return
    raise AssertionError(f"no rule tags {vid}:{pid}")


def test_the_policies_reach_usb_device_nodes_without_0666() -> None:
    uaccess = parse_file(UDEV_DIR / udev.POLICIES["uaccess"])
    plugdev = parse_file(UDEV_DIR / udev.POLICIES["plugdev"])
    assert any('TAG+="uaccess"' in str(a) for a in uaccess.assignments())
    modes = [a.value for a in plugdev.assignments() if a.key == "MODE"]
    assert modes == ["0660"] and not any(is_world_writable(m) for m in modes)


def test_the_permission_message_names_the_rules_to_install() -> None:
    assert udev.CLASSIFY_FILE in UDEV_HINT
    assert all(name in UDEV_HINT for name in udev.POLICIES.values())
