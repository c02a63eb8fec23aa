"""Ctrl-C while numpy's C extensions load reaches spotlab as an ImportError whose context is
the KeyboardInterrupt: it is an interruption (one line, exit 130), not a traceback."""

from __future__ import annotations

import argparse
from typing import Any

import pytest

from spotlab.console import cli
from spotlab.console.errors import EXIT_INTERRUPTED


def _raising(exc_factory: Any) -> Any:
    def build_parser(command: str | None = "*") -> argparse.ArgumentParser:
        parser = argparse.ArgumentParser()
        parser.set_defaults(run=lambda args: exc_factory(), command="x")
        return parser

    return build_parser


def _interrupted_import() -> None:
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        raise ImportError("Importing the numpy C-extensions failed.") from None


def _chained_import() -> None:
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as exc:
        raise ImportError("Importing the numpy C-extensions failed.") from exc


@pytest.mark.parametrize("raiser", [_chained_import, _interrupted_import])
def test_an_import_interrupted_by_ctrl_c_is_an_interruption(
    raiser: Any, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(cli, "build_parser", _raising(raiser))
    assert cli.main([]) == EXIT_INTERRUPTED
    assert capsys.readouterr().err.strip() == "spotlab: error: interrupted"


def test_an_import_error_of_its_own_is_not_hidden(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken() -> None:
        raise ImportError("no module named nothing")

    monkeypatch.setattr(cli, "build_parser", _raising(broken))
    with pytest.raises(ImportError, match="nothing"):
        cli.main([])
    assert not cli._interrupted(ImportError("x"))
