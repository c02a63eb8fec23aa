"""Where the console page's browser time goes: Chromium's CPU with parts of the page off.

Starts ``spotlab console --sim`` and opens its page in headless Chromium (Debian's
``chromium``, driven by Playwright, viewport 1280 x 900). Per variant and round, a fresh
page; once it has live messages, the variant's drawing functions are replaced by ones
that do nothing, and the share of a core all of Chromium's processes use is measured
over ``--seconds`` (with the 3-D updates and live messages the page counted). Variants:

* ``all``: the page as it is;
* ``no3d``, ``noseries``, ``no2d``: without the 3-D view, the marker time series, the
  2-D camera views;
* ``views-off``: without the four views and the device table;
* ``page-off``: also without the mode line, banner, device form and series buffer.

One JSON line per variant and round. Usage: ``python benchmarks/console_page_cost.py
[--seconds 10] [--rounds 2] [--variants all no3d ...]``. The machine's other work
shows in the figures: run it on a quiet machine, rounds alternating the variants.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from console_load import CHROMIUM, CLI, _browser_cpu_s, _spawn, _stop

_OFF = "() => {}"
_VIEWS = ("show3d", "showSeries", "show2d", "showDevices")
VARIANTS: dict[str, tuple[str, ...]] = {
    "all": (),
    "no3d": ("show3d",),
    "noseries": ("showSeries",),
    "no2d": ("show2d",),
    "views-off": _VIEWS,
    "page-off": (*_VIEWS, "showMode", "showBanner", "showDeviceChoices", "keepSeries"),
}


def measure(browser: object, url: str, variant: str, seconds: float) -> dict[str, object]:
    """One variant in a fresh page: Chromium's share of a core over ``seconds``."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})  # type: ignore[attr-defined]
    try:
        page.goto(url)
        page.wait_for_function("window.spotlab.messages > 20", timeout=60_000)
        for name in VARIANTS[variant]:
            page.evaluate(f"window.{name} = {_OFF}")
        time.sleep(2.0)  # what was drawn before settles
        counts = "[performance.now(), window.spotlab.frames3d, window.spotlab.messages]"
        a, c0, t0 = page.evaluate(counts), _browser_cpu_s(), time.monotonic()
        time.sleep(seconds)
        share = (_browser_cpu_s() - c0) / (time.monotonic() - t0)
        b = page.evaluate(counts)
    finally:
        page.close()
    span = (b[0] - a[0]) / 1e3
    return {
        "bench": "console_page_cost", "variant": variant,
        "browser_cpu_share": round(share, 3),
        "page_3d_fps": round((b[1] - a[1]) / span, 1),
        "page_messages_per_s": round((b[2] - a[2]) / span, 1),
        "load_1min": round(os.getloadavg()[0], 2),
    }  # fmt: skip


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        args_console = [*CLI, "console", "--sim", "--no-browser", "--port", "0"]
        proc, url = _spawn([*args_console, "--data", str(folder / "data")], folder, "console")
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
                for n in range(args.rounds):
                    for variant in args.variants:
                        row = {**measure(browser, url, variant, args.seconds), "round": n}
                        print(json.dumps(row), flush=True)
                browser.close()
        finally:
            _stop(proc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
