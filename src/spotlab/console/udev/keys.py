"""The keys of udev(7): which take an ``{attribute}``, which operators, which values udev checks.

A plain table, taken from systemd's ``parse_token`` (``src/udev/udev-rules.c``)
for systemd 252..258, plus the names udev knows besides the keys: removed
legacy keys, built-in commands, and the properties a rule may not set.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

MATCH_OPERATORS = frozenset({"==", "!="})
ASSIGN_OPERATORS = frozenset({"=", "+=", "-=", ":="})
#: For reading them in text: longest first, "=" last so that "==" wins.
OPERATORS_LONGEST_FIRST = ("==", "!=", "+=", "-=", ":=", "=")
#: For naming them in messages.
OPERATORS_SHOWN = ("==", "!=", "=", "+=", "-=", ":=")


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

    @property
    def takes(self) -> str:
        """The operators of this key for a message: "takes '==', '!='"."""
        return "takes " + ", ".join(f"'{o}'" for o in OPERATORS_SHOWN if o in self.ops)


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
