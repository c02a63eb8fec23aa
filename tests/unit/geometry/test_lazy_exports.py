"""spotlab.Camera / spotlab.Rig are the geometry classes, loaded on first use."""

from __future__ import annotations

import subprocess
import sys

import pytest

import spotlab
from spotlab import geometry


def test_lazy_reexports() -> None:
    assert spotlab.Camera is geometry.Camera
    assert spotlab.Rig is geometry.Rig
    with pytest.raises(AttributeError, match="no attribute"):
        _ = spotlab.NoSuchThing  # type: ignore[attr-defined]


def test_import_spotlab_stays_light() -> None:
    code = "import sys, spotlab; print('spotlab.geometry' in sys.modules, 'scipy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
