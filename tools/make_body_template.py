"""Write the ``spotlab-body`` marker template from the simulator's nominal body (seed 0).

Run once (its output is committed as package data)::

    .venv/bin/python tools/make_body_template.py

Neutral pose: the nominal body of ``spotlab sim centroid --motion static`` facing +x on
the volume's centre, averaged over 100 s of its sway (mm; x forward, y left, z up, floor
at z = 0). Structure: rigid clusters and distance links found by
:meth:`MarkerModel.infer` on 30 s of the nominal body's range-of-motion trial
(``--motion rom``): markers whose distances stay within ``TOLERANCE_MM`` make a cluster,
pairs whose distance varies by less than ``LINK_SPREAD_MM`` are links with the range seen.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from spotlab.reconstruction.identification import MarkerModel
from spotlab.reconstruction.identification.template import Template
from spotlab.simulators.centroid_poses import PosedBody

OUT = Path(__file__).resolve().parents[1] / (
    "src/spotlab/reconstruction/identification/templates/spotlab-body.json"
)
TOLERANCE_MM = 2.0
LINK_SPREAD_MM = 450.0


def main() -> int:
    static = PosedBody("static", 0, heading_rad=0.0, spot_mm=(0.0, 0.0))
    neutral = static.all_markers(np.arange(0.0, 100.0, 0.1)).mean(axis=0)
    rom = PosedBody("rom", 0).all_markers(np.arange(0.0, 30.0, 0.02))
    model = MarkerModel.infer(
        static.labels, rom, tolerance_mm=TOLERANCE_MM, link_spread_mm=LINK_SPREAD_MM
    )
    template = Template(
        name="spotlab-body",
        labels=model.labels,
        neutral_mm=neutral,
        segments={s.name: tuple(model.labels[m] for m in s.markers) for s in model.segments},
        links=model.links,
        source="spotlab simulator, nominal 40-marker body (seed 0): neutral pose of "
        "'sim centroid --motion static', clusters and links from 30 s of '--motion rom' "
        f"(tools/make_body_template.py: tolerance {TOLERANCE_MM:g} mm, link spread "
        f"< {LINK_SPREAD_MM:g} mm)",
    )
    template.save(OUT)
    n = [sum(m in (k.a, k.b) for k in model.links) for m in range(len(model.labels))]
    print(f"{OUT}: {len(model.segments)} segments "
          f"{[len(s.markers) for s in model.segments]}, {len(model.links)} links, "
          f"fewest links of a marker {min(n)}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
