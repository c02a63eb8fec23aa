"""The rigid bodies (6D) of a recording's labelled 3-D streams, as one table.

Both families that stream rigid bodies record them raw in their frames: Qualisys
(QTM's 6D component, :func:`spotlab.drivers.qualisys.bodies.bodies_from_recording`)
and NatNet (Motive's rigid bodies, :func:`spotlab.drivers.natnet.bodies.bodies_from_recording`).
Both give a :class:`~spotlab.drivers.recorded_bodies.RigidBodies` (origins in mm,
body-to-world rotation matrices); :func:`write_bodies_csv` writes every stream's as
rows ``stream, body, frame, x_mm, y_mm, z_mm, qx, qy, qz, qw`` (``nan`` where the
body was not tracked), which ``spotlab export REC --c3d OUT`` writes beside ``OUT``
as ``OUT``'s stem + ``.bodies.csv``.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt

from spotlab.drivers.natnet import bodies as natnet_bodies
from spotlab.drivers.qualisys.bodies import bodies_from_recording as qualisys_bodies
from spotlab.drivers.recorded_bodies import RigidBodies
from spotlab.io.journal import JournalReader

F64 = npt.NDArray[np.float64]

COLUMNS = ("stream", "body", "frame", "x_mm", "y_mm", "z_mm", "qx", "qy", "qz", "qw")


def quaternions(r: F64) -> F64:
    """Unit quaternions (..., 4) x, y, z, w (w >= 0) of rotation matrices (..., 3, 3).

    Shepperd's method: the largest of 4w², 4x², 4y², 4z² is taken from the diagonal,
    the others from off-diagonal sums and differences, so no small component comes
    from the square root of a difference of nearly equal numbers (rotations near
    180 degrees keep their precision). NaN matrices give NaN quaternions.
    """
    r = np.asarray(r, dtype=np.float64)
    r00, r11, r22 = r[..., 0, 0], r[..., 1, 1], r[..., 2, 2]
    big = np.stack([1 + r00 + r11 + r22, 1 + r00 - r11 - r22, 1 - r00 + r11 - r22,
                    1 - r00 - r11 + r22], axis=-1)  # fmt: skip
    pick = np.argmax(np.nan_to_num(big, nan=-1.0), axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(big, pick[..., None], -1)[..., 0], 1e-300))
    d21, d02, d10 = (
        r[..., 2, 1] - r[..., 1, 2],
        r[..., 0, 2] - r[..., 2, 0],
        r[..., 1, 0] - r[..., 0, 1],
    )
    s21, s02, s10 = (
        r[..., 2, 1] + r[..., 1, 2],
        r[..., 0, 2] + r[..., 2, 0],
        r[..., 1, 0] + r[..., 0, 1],
    )
    cases = [
        (d21 / s, d02 / s, d10 / s, s / 4),  # w largest
        (s / 4, s10 / s, s02 / s, d21 / s),  # x largest
        (s10 / s, s / 4, s21 / s, d02 / s),  # y largest
        (s02 / s, s21 / s, s / 4, d10 / s),  # z largest
    ]
    q = np.zeros((*r.shape[:-2], 4))
    for k, comps in enumerate(cases):
        sel = pick == k
        q[sel] = np.stack([c[sel] for c in comps], axis=-1)
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q


def recording_bodies(path: str | os.PathLike[str]) -> list[tuple[RigidBodies, F64]]:
    """Every stream's rigid bodies and their quaternions (F, B, 4), x, y, z, w.

    NatNet's quaternions are Motive's own; Qualisys's come from QTM's rotation matrices.
    Streams that describe no rigid body are left out.
    """
    out: list[tuple[RigidBodies, F64]] = []
    for name, meta in JournalReader(path).streams.items():
        family = meta.get("family")
        if family == "natnet" and meta.get("rigid_bodies"):
            got = natnet_bodies.bodies_from_recording(path, name)
            out.append((got.bodies, got.quaternions))
        elif family == "qualisys" and ((meta.get("spec") or {}).get("metadata") or {}).get(
            "bodies"
        ):
            bodies = qualisys_bodies(path, name)
            out.append((bodies, quaternions(bodies.rotations)))
    return out


def write_bodies_csv(path: Path, found: list[tuple[RigidBodies, F64]]) -> int:
    """Write the rows of :data:`COLUMNS` (one per frame and body). Returns the rows."""
    rows = 0
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(COLUMNS)
        for bodies, quats in found:
            for i, frame in enumerate(bodies.seq.tolist()):
                for j, name in enumerate(bodies.names):
                    values = [*bodies.positions[i, j].tolist(), *quats[i, j].tolist()]
                    cells = ["nan" if not np.isfinite(v) else f"{v:.6f}" for v in values]
                    out.writerow([bodies.stream, name, frame, *cells])
                    rows += 1
    return rows


def bodies_path(out: Path) -> Path:
    """Where the bodies of an export to ``out`` go: ``out``'s stem + ``.bodies.csv``."""
    return out.with_name(out.stem + ".bodies.csv")
