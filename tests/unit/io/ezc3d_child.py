"""Read a C3D file with ezc3d in a child process (a segfault there fails the test, not pytest)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

_DUMP = """
import json, sys, numpy as np, ezc3d
c = ezc3d.c3d(sys.argv[1])
p = c["parameters"]
def value(group, name):
    g = {k.upper(): v for k, v in p.get(group, {}).items() if k != "__METADATA__"}
    v = g.get(name, {}).get("value")
    if v is None:
        return None
    return np.asarray(v).tolist() if not isinstance(v, list) else [str(s) for s in v]
wanted = json.loads(sys.argv[3])
params = {key: value(*key.split(":")) for key in wanted}
groups = {g: sorted(k.upper() for k in v if k != "__METADATA__")
          for g, v in p.items() if isinstance(v, dict) and g != "__METADATA__"}
np.savez(sys.argv[2], points=c["data"]["points"], analogs=c["data"]["analogs"],
         first=c["header"]["points"]["first_frame"], last=c["header"]["points"]["last_frame"],
         meta=json.dumps({"params": params, "groups": groups}))
"""


def ezc3d_dump(path: Path, out: Path, params: tuple[str, ...] = ()) -> dict[str, Any]:
    """ezc3d's view of ``path``.

    Returns
    -------
    dict
        ``points`` (F, M, 3) with NaN where ezc3d has none, ``analog`` (S, A),
        ``first`` and ``last`` frame (ezc3d counts from 0), ``params`` (the values of
        the ``GROUP:NAME`` keys asked for, None when absent) and ``groups`` (group
        name to its parameter names).
    """
    pytest.importorskip("ezc3d")
    done = subprocess.run(
        [sys.executable, "-c", _DUMP, str(path), str(out), json.dumps(list(params))],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, f"ezc3d failed ({done.returncode}): {done.stderr[-800:]}"
    with np.load(out) as data:
        meta = json.loads(str(data["meta"]))
        return {
            "points": data["points"][:3].transpose(2, 1, 0),  # (4, M, F) -> (F, M, 3)
            "analog": data["analogs"][0].T if data["analogs"].size else np.zeros((0, 0)),
            "first": int(data["first"]),
            "last": int(data["last"]),
            **meta,
        }
