"""Every compiled kernel is built where a C compiler exists (setup.py warns and goes on
without one, so a failed build would otherwise pass unnoticed as slower numpy twins)."""

from __future__ import annotations

import importlib
import shutil
from pathlib import Path

import pytest

from spotlab.core import native

SRC = Path(__file__).resolve().parents[2] / "src"


def _kernel_names() -> list[str]:
    return [
        ".".join(c.relative_to(SRC).with_suffix("").parts)
        for c in sorted(SRC.glob("spotlab/**/_c_*.c"))
    ]


def test_the_kernels_are_found() -> None:
    assert len(_kernel_names()) >= 4, _kernel_names()  # gcv, bands, bspline, frame


@pytest.mark.parametrize("module", _kernel_names())
def test_every_kernel_is_built_where_a_compiler_exists(module: str) -> None:
    assert shutil.which("cc") or shutil.which("gcc"), "no C compiler on this machine"
    importlib.import_module(module)


def test_no_native_environment_variable_keeps_the_twins(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(native.NO_NATIVE_ENV, "1")
    assert native.disabled()
    assert native.load("spotlab.core.native") is None
    monkeypatch.setenv(native.NO_NATIVE_ENV, "0")
    assert native.load("spotlab.core.native") is native
    assert native.load("spotlab.core._c_no_such_kernel") is None
