"""What the simulated QTM measures: the walking body's labelled markers, rigid bodies, 2-D.

The labelled 3-D markers are the first ``markers`` of the video-centroid
simulator's 40-marker walking body (:class:`~spotlab.simulators.centroid_body.GaitBody`,
subject ``seed``), so a QTM recording and a centroid recording of one seed see
the same subject. The 6DOF bodies are the rigid clusters of that body whose
markers are all labelled (pelvis, head, thorax); a body's pose is computed from
its markers each frame. The 2-D markers are the labelled markers projected into
the cameras of :func:`~spotlab.simulators.rigs.ring_rig` (1/64 px units).
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import escape

import numpy as np
import numpy.typing as npt

from spotlab.simulators.centroid_body import BODY_LABELS, GaitBody
from spotlab.simulators.rigs import ring_rig

F64 = npt.NDArray[np.float64]

#: Rigid clusters: body name -> its markers (the first pair's middle minus the second
#: pair's gives the body's x axis, the first marker minus the second its y axis).
CLUSTERS = (
    ("pelvis", ("LASI", "RASI", "LPSI", "RPSI")),
    ("head", ("LFHD", "RFHD", "LBHD", "RBHD")),
    ("thorax", ("CLAV", "STRN", "C7", "T10")),
)
#: Marker diameter (mm) for the 2-D component's diameters.
MARKER_MM = 12.0
#: 2-D coordinates are sent in these units per pixel.
SUBPIXELS = 64
MAX_MARKERS = len(BODY_LABELS)
#: Frames computed at once (the body model is vectorised over time).
CHUNK = 64


def cluster_pose(points: F64) -> tuple[F64, F64]:
    """A cluster's pose from its 4 markers (K, 4, 3) mm.

    Returns
    -------
    origin : ndarray, shape (K, 3)
        The markers' mean (mm).
    rotation : ndarray, shape (K, 3, 3)
        Body to world: columns are the body's x, y, z axes in the world.
    """
    origin = points.mean(axis=1)
    y = points[:, 0] - points[:, 1]
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    v = 0.5 * (points[:, 0] + points[:, 1]) - 0.5 * (points[:, 2] + points[:, 3])
    x = v - np.sum(v * y, axis=1, keepdims=True) * y
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    z = np.cross(x, y)
    return origin, np.stack([x, y, z], axis=2)


@dataclass(frozen=True)
class SceneFrame:
    """One frame of the scene: labelled markers (M, 3) mm, bodies (B, 3) mm and (B, 3, 3)."""

    markers: F64
    body_positions: F64
    body_rotations: F64


class QualisysScene:
    """The measured world of the simulated QTM.

    Parameters
    ----------
    markers : int
        Labelled markers, 1-40 (the walking body's first ones).
    cameras : int
        Cameras of the ring, 1-16.
    rate_hz : float
        Capture rate (Hz).
    seed : int
        The subject (0: the nominal body).
    clock_drift_ppm : float
        QTM's clock error: its timestamps run fast by this many parts per million of
        the true capture times (default 0; |drift| at most 10 000 ppm).

    Raises
    ------
    ValueError
        For counts or a rate out of range.
    """

    def __init__(
        self,
        markers: int = 40,
        cameras: int = 8,
        rate_hz: float = 100.0,
        seed: int = 0,
        clock_drift_ppm: float = 0.0,
    ):
        if not 1 <= markers <= MAX_MARKERS:
            raise ValueError(f"--markers must be 1 to {MAX_MARKERS}, got {markers}")
        if not 1 <= cameras <= 16:
            raise ValueError(f"--cameras must be 1 to 16, got {cameras}")
        if not 1.0 <= rate_hz <= 2000.0:
            raise ValueError(f"--rate must be 1 to 2000 Hz, got {rate_hz:g}")
        if not abs(clock_drift_ppm) <= 1e4:
            raise ValueError(f"--clock-drift-ppm must be -10000 to 10000, got {clock_drift_ppm:g}")
        self.clock_drift_ppm = float(clock_drift_ppm)
        self.n_markers = markers
        self.rate_hz = float(rate_hz)
        self.seed = seed
        self.labels = tuple(BODY_LABELS[:markers])
        self.body = GaitBody.for_seed(seed)
        self.rig = ring_rig(max(cameras, 2), seed=seed)
        self.cameras = self.rig.cameras[:cameras]
        index = {name: i for i, name in enumerate(self.labels)}
        self.clusters = [
            (name, np.array([index[m] for m in members]))
            for name, members in CLUSTERS
            if all(m in index for m in members)
        ]
        self.body_names = tuple(name for name, _ in self.clusters)
        first = self.body.all_markers(np.zeros(1))[0, :markers]
        self._chunk: tuple[int, F64, F64, F64] | None = None
        self._local = {}
        for name, idx in self.clusters:
            o, r = cluster_pose(first[idx][None])
            self._local[name] = (first[idx] - o[0]) @ r[0]

    def time_s(self, frame: int) -> float:
        """Capture time (s) of frame number ``frame`` (from 1)."""
        return (frame - 1) / self.rate_hz

    def timestamp_us(self, frame: int) -> int:
        """QTM's timestamp (µs) of frame number ``frame``: its capture time on QTM's clock
        (fast by ``clock_drift_ppm``)."""
        return round((frame - 1) * 1e6 / self.rate_hz * (1.0 + self.clock_drift_ppm * 1e-6))

    def frame(self, frame: int) -> SceneFrame:
        """The scene at frame number ``frame`` (computed :data:`CHUNK` frames at a time)."""
        first = frame - (frame - 1) % CHUNK
        if self._chunk is None or self._chunk[0] != first:
            times = (first - 1 + np.arange(CHUNK)) / self.rate_hz
            X = self.body.all_markers(times)[:, : self.n_markers]
            pos = np.zeros((CHUNK, len(self.clusters), 3))
            rot = np.zeros((CHUNK, len(self.clusters), 3, 3))
            for b, (_, idx) in enumerate(self.clusters):
                pos[:, b], rot[:, b] = cluster_pose(X[:, idx])
            self._chunk = (first, X, pos, rot)
        _, X, pos, rot = self._chunk
        k = frame - first
        return SceneFrame(X[k], pos[k], rot[k])

    def view_2d(self, markers: F64) -> list[tuple[npt.NDArray[np.int32], npt.NDArray[np.uint16]]]:
        """Per camera, the markers in its image: sub-pixel (K, 2) and diameters (K, 2)."""
        out = []
        for cam in self.cameras:
            uv = cam.project(markers)
            depth = (markers @ cam.R.T + cam.t)[:, 2]
            w, h = cam.size
            ok = np.isfinite(uv).all(axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] < w)
            ok &= (uv[:, 1] >= 0) & (uv[:, 1] < h)
            d_px = cam.K[0, 0] * MARKER_MM / np.where(ok, depth, 1.0)
            xy = np.round(uv[ok] * SUBPIXELS).astype(np.int32)
            d = np.clip(np.round(d_px[ok] * SUBPIXELS), 1, 65535).astype(np.uint16)
            out.append((xy, np.stack([d, d], axis=1)))
        return out

    def parameters_xml(self, sections: set[str]) -> str:
        """The parameters document with the sections asked for (``general``, ``3d``,
        ``6d``), qualisys.md §6."""
        parts = ["<QTM_Parameters_Ver_1.25>"]
        if "general" in sections:
            parts.append(self._general())
        if "3d" in sections:
            labels = "".join(
                f"<Label><Name>{escape(n)}</Name><RGBColor>16711680</RGBColor></Label>"
                for n in self.labels
            )
            parts.append(
                f"<The_3D><AxisUpwards>+Z</AxisUpwards><Labels>{len(self.labels)}</Labels>"
                f"{labels}</The_3D>"
            )
        if "6d" in sections:
            bodies = []
            for name, idx in self.clusters:
                pts = "".join(
                    f'<Point X="{x:.3f}" Y="{y:.3f}" Z="{z:.3f}" Virtual="0" PhysicalId="0" '
                    f'Name="{self.labels[i]}"/>'
                    for i, (x, y, z) in zip(idx, self._local[name], strict=True)
                )
                bodies.append(f"<Body><Name>{name}</Name><Points>{pts}</Points></Body>")
            parts.append(f"<The_6D><Bodies>{len(bodies)}</Bodies>{''.join(bodies)}</The_6D>")
        parts.append("</QTM_Parameters_Ver_1.25>")
        return "".join(parts)

    def _general(self) -> str:
        cams = []
        for i, cam in enumerate(self.cameras):
            c = cam.center
            rot = "".join(
                f"<Rot_{r + 1}_{k + 1}>{cam.R[k, r]:.6f}</Rot_{r + 1}_{k + 1}>"
                for r in range(3)
                for k in range(3)
            )
            cams.append(
                f"<Camera><ID>{i + 1}</ID><Model>spotlab simulated</Model>"
                f"<Serial>{90001 + i}</Serial><Mode>Marker</Mode>"
                f"<Position><X>{c[0]:.3f}</X><Y>{c[1]:.3f}</Y><Z>{c[2]:.3f}</Z>{rot}</Position>"
                f"</Camera>"
            )
        return (
            f"<General><Frequency>{self.rate_hz:g}</Frequency><Capture_Time>60</Capture_Time>"
            f"{''.join(cams)}</General>"
        )
