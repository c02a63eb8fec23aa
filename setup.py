"""Build step of spotlab's compiled kernels; everything else is in pyproject.toml.

Every ``src/spotlab/**/_c_*.c`` file is a CPython extension module of the package it
sits in (``src/spotlab/kinematics/_c_gcv.c`` -> ``spotlab.kinematics._c_gcv``). They
use the C API and the buffer protocol only (code shared by several may sit in a
``_*.h`` header beside them), so building needs a C compiler and no
numpy headers. Each has a pure numpy twin that gives the same results: a machine
without a compiler still installs (with one warning line per kernel) and runs the
twins, only slower. ``spotlab.core.native.compiled()`` says which kernels are in use.
"""

from __future__ import annotations

import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: IEEE arithmetic in the written order (no fused multiply-add contraction, no fast
#: math), so that a kernel's results can be compared with its numpy twin's.
_CFLAGS = ["-O3", "-std=c99", "-ffp-contract=off", "-fno-fast-math"]


def _kernels() -> list[Extension]:
    root = Path("src")
    return [
        Extension(
            ".".join(source.relative_to(root).with_suffix("").parts),
            [source.as_posix()],
            depends=[header.as_posix() for header in sorted(source.parent.glob("_*.h"))],
            extra_compile_args=[] if sys.platform == "win32" else _CFLAGS,
        )
        for source in sorted(root.glob("spotlab/**/_c_*.c"))
    ]


class _OptionalBuildExt(build_ext):
    """Build each kernel, or warn in one line and leave its numpy twin in use."""

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:  # any compiler failure leaves the twin
            print(f"spotlab: warning: {ext.name} not compiled ({exc}); its numpy twin runs")

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # no compiler at all
            print(f"spotlab: warning: compiled kernels not installed ({exc}); numpy twins run")


setup(ext_modules=_kernels(), cmdclass={"build_ext": _OptionalBuildExt})
