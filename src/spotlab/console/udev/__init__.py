"""``spotlab udev``: show, check and install the udev rules shipped with spotlab.

Two halves, one module per job:

* a strict rules parser that never touches the system: :mod:`.keys` (the table
  of udev keys and their operators), :mod:`.lexer` (lines to ``KEY{attr}OP"value"``
  pairs), :mod:`.values` (MODE bits, substitutions, OPTIONS), :mod:`.checks`
  (what udev would reject or misread), :mod:`.model` (pairs, rules, issues) and
  :mod:`.rules` (:func:`parse_rules`, :func:`check_file`, :class:`RulesFile`);
* the command: :mod:`.shipped` (finding the packaged rules, ``show``, ``check``),
  :mod:`.installer` (:func:`plan_install`, :func:`install`), :mod:`.install_result`
  (:class:`InstallResult` for text or JSON) and :mod:`.cli` (argparse hooks).

Everything public is re-exported here. Settings such as ``RULES_PACKAGE`` or
``LIVE_RULES_DIRS`` are read where they are defined: to change them (in tests),
patch :mod:`.shipped` or :mod:`.installer`, not this package.
"""

from __future__ import annotations

from spotlab.console.udev.cli import add_udev_parser, run_udev
from spotlab.console.udev.install_result import (
    CommandRun,
    FileAction,
    FileStatus,
    InstallResult,
    PlannedFile,
)
from spotlab.console.udev.installer import (
    DEFAULT_TARGET,
    LIVE_RULES_DIRS,
    RELOAD_COMMANDS,
    RULES_FILE_MODE,
    install,
    plan_install,
)
from spotlab.console.udev.keys import (
    ASSIGN_OPERATORS,
    BUILTINS,
    KEYS,
    LEGACY_KEYS,
    MATCH_OPERATORS,
    READ_ONLY_PROPERTIES,
    KeySpec,
)
from spotlab.console.udev.model import Assignment, Code, Issue, Rule, Severity
from spotlab.console.udev.rules import (
    RulesFile,
    UdevRulesError,
    check_file,
    check_text,
    parse_file,
    parse_rules,
)
from spotlab.console.udev.shipped import (
    CLASSIFY_FILE,
    DEFAULT_POLICY,
    POLICIES,
    RULES_PACKAGE,
    UdevError,
    check_rules,
    policy_rules,
    rules_dir,
    shipped_rules,
    show_rules,
)
from spotlab.console.udev.values import format_problem, is_option, is_world_writable, mode_bits

__all__ = [
    "ASSIGN_OPERATORS",
    "BUILTINS",
    "CLASSIFY_FILE",
    "DEFAULT_POLICY",
    "DEFAULT_TARGET",
    "KEYS",
    "LEGACY_KEYS",
    "LIVE_RULES_DIRS",
    "MATCH_OPERATORS",
    "POLICIES",
    "READ_ONLY_PROPERTIES",
    "RELOAD_COMMANDS",
    "RULES_FILE_MODE",
    "RULES_PACKAGE",
    "Assignment",
    "Code",
    "CommandRun",
    "FileAction",
    "FileStatus",
    "InstallResult",
    "Issue",
    "KeySpec",
    "PlannedFile",
    "Rule",
    "RulesFile",
    "Severity",
    "UdevError",
    "UdevRulesError",
    "add_udev_parser",
    "check_file",
    "check_rules",
    "check_text",
    "format_problem",
    "install",
    "is_option",
    "is_world_writable",
    "mode_bits",
    "parse_file",
    "parse_rules",
    "plan_install",
    "policy_rules",
    "rules_dir",
    "run_udev",
    "shipped_rules",
    "show_rules",
]
