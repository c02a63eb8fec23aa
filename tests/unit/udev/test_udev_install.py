"""spotlab.console.udev: plan, dry run, --yes into a temporary folder, reload guard, CLI."""

from __future__ import annotations

import argparse
import json
import os
import stat
import sys
from pathlib import Path

import pytest

from spotlab.console import udev
from spotlab.console.udev import PlannedFile, UdevError, install, plan_install
from spotlab.console.udev import installer as udev_installer
from spotlab.console.udev import shipped as udev_shipped

ROOT = Path(__file__).resolve().parents[3]


def _listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture
def fake_udevadm(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A udevadm on PATH that only records its arguments (the real one must never run)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "udevadm.log"
    script = bin_dir / "udevadm"
    script.write_text(f'#!/bin/sh\necho "$@" >> {log}\n')
    script.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}")
    return log


@pytest.fixture
def target(tmp_path: Path) -> Path:
    folder = tmp_path / "rules.d"
    folder.mkdir()
    return folder


# ----------------------------------------------------------------------------- plan


@pytest.mark.parametrize("policy", ["uaccess", "plugdev"])
def test_plan_is_classification_plus_one_policy(policy: str) -> None:
    plan = plan_install(policy)
    assert [p.path for p in plan] == [
        Path("/etc/udev/rules.d/60-spotlab.rules"),
        Path(f"/etc/udev/rules.d/61-spotlab-{policy}.rules"),
    ]
    for path, content in plan:  # unpacks as (path, content)
        assert content == (ROOT / "udev" / path.name).read_text()


def test_plan_default_policy_is_uaccess(target: Path) -> None:
    assert [p.path.name for p in plan_install(target=target)][-1] == "61-spotlab-uaccess.rules"


def test_unknown_policy() -> None:
    with pytest.raises(UdevError, match="unknown udev policy 'world'"):
        plan_install("world")


def test_rules_are_found_through_importlib_resources(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    package = tmp_path / "site" / "spotlab_fake_udev_data"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    for rules in (ROOT / "udev").glob("*.rules"):
        (package / rules.name).write_text(rules.read_text())
    (package / "99-extra.rules").write_text('KERNEL=="x", TAG+="extra"\n')
    monkeypatch.syspath_prepend(str(package.parent))
    monkeypatch.setattr(udev_shipped, "RULES_PACKAGE", "spotlab_fake_udev_data")
    try:
        assert Path(str(udev.rules_dir())) == package
        assert "99-extra.rules" in udev.shipped_rules()
    finally:
        sys.modules.pop("spotlab_fake_udev_data", None)


def test_rules_fall_back_to_the_checkout(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(udev_shipped, "RULES_PACKAGE", "spotlab_no_such_package_for_udev")
    assert Path(str(udev.rules_dir())) == ROOT / "udev"


def test_missing_rules_are_a_clear_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(udev_shipped, "RULES_PACKAGE", "spotlab_no_such_package_for_udev")
    monkeypatch.setattr(udev_shipped, "_checkout_rules_dir", lambda: tmp_path)
    with pytest.raises(UdevError, match="reinstall spotlab"):
        plan_install()


# ----------------------------------------------------------------------------- dry run


def test_without_yes_nothing_is_written(target: Path, fake_udevadm: Path) -> None:
    plan = plan_install("uaccess", target)
    result = install(plan, yes=False, reload=True)
    assert _listing(target) == []
    assert not fake_udevadm.exists()
    assert result.written is False
    assert [(f.path, f.status) for f in result.files] == [(p.path, "create") for p in plan]
    assert "Nothing was written." in result.to_text()
    assert any("--yes" in step for step in result.next_steps)
    assert "--reload does nothing without --yes" in result.warnings


def test_dry_run_into_a_missing_folder_creates_nothing(tmp_path: Path) -> None:
    missing = tmp_path / "nope" / "rules.d"
    result = install(plan_install("plugdev", missing))
    assert not missing.exists() and not missing.parent.exists()
    assert any("does not exist" in w for w in result.warnings)


def test_dry_run_says_root_is_needed(target: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(udev_installer, "_writable", lambda folder: False)
    result = install(plan_install("uaccess", target))
    assert result.writable is False
    assert 'sudo "$(command -v spotlab)" udev install --policy uaccess' in result.to_text()


# ----------------------------------------------------------------------------- --yes


@pytest.mark.parametrize("policy", ["uaccess", "plugdev"])
def test_yes_writes_exactly_the_planned_files(target: Path, policy: str) -> None:
    plan = plan_install(policy, target)
    result = install(plan, yes=True)
    assert result.written and result.ok
    assert _listing(target) == sorted(p.path.name for p in plan)
    for path, content in plan:
        assert path.read_text() == content
        assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [f.status for f in result.files] == ["create", "create"]


def test_second_install_is_unchanged_and_a_changed_file_is_replaced(target: Path) -> None:
    plan = plan_install("uaccess", target)
    install(plan, yes=True)
    assert [f.status for f in install(plan, yes=True).files] == ["unchanged", "unchanged"]
    plan[0].path.write_text("# edited by hand\n")
    result = install(plan, yes=True)
    assert [f.status for f in result.files] == ["replace", "unchanged"]
    assert plan[0].path.read_text() == plan[0].content
    assert _listing(target) == sorted(p.path.name for p in plan)


def test_yes_into_a_missing_folder_fails(tmp_path: Path) -> None:
    with pytest.raises(UdevError, match="does not exist"):
        install(plan_install("uaccess", tmp_path / "missing"), yes=True)


def test_yes_into_an_unwritable_folder_suggests_sudo(
    target: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(udev_installer, "_writable", lambda folder: False)
    with pytest.raises(UdevError, match=r"permission denied.*sudo"):
        install(plan_install("plugdev", target), yes=True)
    assert _listing(target) == []


def test_permission_error_while_writing_suggests_sudo(
    target: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(path: Path, content: str) -> None:
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(udev_installer, "_atomic_write", refuse)
    with pytest.raises(UdevError, match="sudo"):
        install(plan_install("uaccess", target), yes=True)


def test_other_policy_already_installed_is_reported(target: Path) -> None:
    install(plan_install("plugdev", target), yes=True)
    result = install(plan_install("uaccess", target), yes=True)
    assert any("61-spotlab-plugdev.rules is also installed" in w for w in result.warnings)


def test_missing_plugdev_group_is_reported(target: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(udev_installer, "_group_exists", lambda name: False)
    result = install(plan_install("plugdev", target))
    assert any("group plugdev does not exist" in w for w in result.warnings)


def test_plan_from_several_folders_is_refused(tmp_path: Path) -> None:
    plan = [PlannedFile(tmp_path / "a" / "x.rules", ""), PlannedFile(tmp_path / "y.rules", "")]
    with pytest.raises(UdevError, match="one folder"):
        install(plan)


# ----------------------------------------------------------------------------- reload


def test_yes_does_not_reload_unless_asked(
    target: Path, fake_udevadm: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(udev_installer, "LIVE_RULES_DIRS", (target,))
    result = install(plan_install("uaccess", target), yes=True)
    assert not fake_udevadm.exists()
    assert result.commands == []
    assert any("udevadm control --reload-rules" in step for step in result.next_steps)


def test_reload_runs_udevadm_for_a_live_folder(
    target: Path, fake_udevadm: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(udev_installer, "LIVE_RULES_DIRS", (target,))
    result = install(plan_install("uaccess", target), yes=True, reload=True)
    assert result.ok
    assert [run.args[1:] for run in result.commands] == [cmd[1:] for cmd in udev.RELOAD_COMMANDS]
    assert fake_udevadm.read_text().splitlines() == [
        "control --reload-rules",
        "trigger --action=change --subsystem-match=usb --subsystem-match=tty "
        "--subsystem-match=usb-serial",
    ]


def test_reload_is_skipped_for_a_folder_udev_does_not_read(
    target: Path, fake_udevadm: Path
) -> None:
    result = install(plan_install("uaccess", target), yes=True, reload=True)
    assert not fake_udevadm.exists()
    assert any("not a folder udev reads" in w for w in result.warnings)


def test_reload_failure_is_reported(
    target: Path, fake_udevadm: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    script = fake_udevadm.parent / "bin" / "udevadm"
    script.write_text("#!/bin/sh\necho 'Failed to send reload request' >&2\nexit 1\n")
    monkeypatch.setattr(udev_installer, "LIVE_RULES_DIRS", (target,))
    result = install(plan_install("uaccess", target), yes=True, reload=True)
    assert not result.ok
    assert len(result.commands) == 1
    assert "Failed to send reload request" in result.to_text()


# ----------------------------------------------------------------------------- command line


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="spotlab")
    sub = parser.add_subparsers(dest="command")
    udev.add_udev_parser(sub)
    args = parser.parse_args(argv)
    return int(args.run(args))


def test_cli_install_json_dry_run_and_yes(target: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["udev", "install", "--target", str(target), "--json"]) == 0
    dry = json.loads(capsys.readouterr().out)
    assert dry["written"] is False and dry["policy"] == "uaccess"
    assert _listing(target) == []
    assert _run(["udev", "install", "--policy", "plugdev", "--target", str(target), "--yes"]) == 0
    assert "Installed the spotlab udev rules (policy: plugdev)" in capsys.readouterr().out
    assert _listing(target) == ["60-spotlab.rules", "61-spotlab-plugdev.rules"]


def test_cli_install_error_as_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["udev", "install", "--target", str(tmp_path / "missing"), "--yes", "--json"]
    assert _run(argv) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and "does not exist" in out["error"]


def test_cli_show(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["udev", "show", "--policy", "uaccess"]) == 0
    text = capsys.readouterr().out
    assert "# ==> 60-spotlab.rules <==" in text and 'TAG+="uaccess"' in text
    assert 'plugdev"' not in text
    assert _run(["udev", "show", "--json"]) == 0
    names = [f["name"] for f in json.loads(capsys.readouterr().out)["files"]]
    assert names == ["60-spotlab.rules", "61-spotlab-plugdev.rules", "61-spotlab-uaccess.rules"]


def test_cli_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["udev", "check"]) == 0
    assert "0 errors" in capsys.readouterr().out
    bad = tmp_path / "99-bad.rules"
    bad.write_text('SUBSYSTEM=="usb", ATTRS{idVendor}=="03e7", MODE="0666"\n')
    assert _run(["udev", "check", str(bad)]) == 1
    assert f'{bad}:1:44: error: MODE="0666"' in capsys.readouterr().out
    warn = tmp_path / "98-warn.rules"
    warn.write_text('KERNEL=="x"\n')
    assert _run(["udev", "check", str(warn)]) == 0
    assert _run(["udev", "check", "--strict", "--json", str(warn)]) == 1
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["ok"] is False


def test_cli_check_missing_file(tmp_path: Path) -> None:
    with pytest.raises(UdevError, match="cannot read"):
        _run(["udev", "check", str(tmp_path / "nope.rules")])
