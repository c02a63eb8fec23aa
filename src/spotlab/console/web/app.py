"""The console's web app: the page, the JSON API and the live WebSocket (docs/console.md).

Every ``/api`` route asks for the token when one is set (header ``Authorization: Bearer
T`` or query ``?token=T``); the page and its two files are public (they hold no data).
The WebSocket reads the latest values the acquisition keeps (``live_view``) at
``LIVE_HZ`` (the 3-D markers; the tables and 2-D views at ``SLOW_HZ``); it never waits
on, nor is waited for by, the acquisition.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import time
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from spotlab import __version__
from spotlab.console.web.acquisition import Acquisition
from spotlab.console.web.calibration_wizard import CalibrationWizard
from spotlab.console.web.export import export_trial
from spotlab.console.web.lab_setup import with_rate, with_settings
from spotlab.console.web.link_health import LinkHealth
from spotlab.console.web.processing_jobs import Processor
from spotlab.console.web.trials import TrialInfo
from spotlab.processing.errors import InputError

__all__ = ["LIVE_HZ", "make_app"]

#: Messages a second on /api/live, each with the latest 3-D markers (the page draws the
#: 3-D view at this rate at most: 10 % above the 30 a second it is to reach, not more,
#: since every drawn frame costs a browser without a GPU about 4 ms of CPU; 40 before).
LIVE_HZ = 33.0
#: Messages a second that also hold the status, device rows and 2-D views (``slow``
#: counts them): encoding, sending and drawing 8 cameras' blobs 40 times a second would
#: cost the acquisition's interpreter and the browser more than the operator sees.
SLOW_HZ = 10.0
STATIC = Path(__file__).parent / "static"


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


def make_app(
    acq: Acquisition, token: str | None = None, processor: Processor | None = None
) -> Starlette:
    """The Starlette app of a running :class:`Acquisition`.

    ``processor`` processes trials for ``/api/trials/{id}/process`` (default: one of the
    acquisition's data folder and lab).
    """
    lab = acq.plan.lab
    jobs = processor or Processor(acq.store, lab.rig, lab.model, lab.path)
    health = LinkHealth(acq.devices)
    health.start()
    wizard = CalibrationWizard(acq, jobs)

    def allowed(given: str | None) -> bool:
        return token is None or (given is not None and hmac.compare_digest(given, token))

    def token_of(request: Request | WebSocket) -> str | None:
        auth = request.headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            return auth[7:].strip()
        return request.query_params.get("token")

    async def guard(request: Request) -> JSONResponse | None:
        if not allowed(token_of(request)):
            return _error(401, "a valid token is needed (Authorization: Bearer T or ?token=T)")
        return None

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", media_type="text/html")

    async def status(request: Request) -> Response:
        return await guard(request) or JSONResponse(
            {"version": __version__, **acq.status(), "live_latency": acq.live_latency()}
        )

    async def devices(request: Request) -> Response:
        return await guard(request) or JSONResponse({"devices": acq.devices()})

    async def reconnect(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        name = request.path_params["name"]
        if name not in acq.plan.names():
            return _error(404, f"no device {name!r} in the lab")
        try:
            how = acq.reconnect(name)
        except InputError as exc:
            return _error(409, str(exc))
        return JSONResponse(
            {"device": name, "restarting": how == "session", "reconnecting": how},
            status_code=202,
        )

    async def configure(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        name = request.path_params["name"]
        if name not in acq.plan.names():
            return _error(404, f"no device {name!r} in the lab")
        try:
            raw = await body(request)
            if "settings" in raw:  # any of the family's settings, as in a lab file
                acq.restart(with_settings(acq.plan, name, raw["settings"]))
                done = {"settings": raw["settings"]}
            else:
                acq.restart(with_rate(acq.plan, name, raw.get("rate_hz")))
                done = {"rate_hz": float(raw["rate_hz"])}
        except InputError as exc:
            return _error(409 if "being recorded" in str(exc) else 400, str(exc))
        return JSONResponse({"device": name, **done, "restarting": True})

    async def calibration(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        step = request.path_params.get("step")
        if request.url.path.endswith("/figure"):
            try:
                return FileResponse(wizard.figure(), media_type="image/png")
            except InputError as exc:
                return _error(404, str(exc))
        if step is None:
            return JSONResponse(wizard.snapshot())
        try:
            raw = await body(request)
            if step in ("wand", "lframe"):
                wizard.record(
                    step, raw.get("subject"), raw.get("session"), raw.get("seconds"),
                    raw.get("device"),
                )  # fmt: skip
            elif step == "run":
                wizard.calibrate()
            elif step == "accept":
                wizard.accept()
            else:
                return _error(404, f"no calibration step {step!r}")
        except InputError as exc:
            return _error(409 if "busy" in str(exc) or "being" in str(exc) else 400, str(exc))
        return JSONResponse(wizard.snapshot(), status_code=202 if step != "accept" else 200)

    async def link_health(request: Request) -> Response:
        return await guard(request) or JSONResponse(health.snapshot())

    async def trials(request: Request) -> Response:
        return await guard(request) or JSONResponse(
            {"trials": [t.to_dict() for t in acq.store.all()]}
        )

    async def body(request: Request) -> dict[str, Any]:
        try:
            raw = await request.json()
        except (ValueError, UnicodeDecodeError) as exc:
            raise InputError(f"the body is not JSON: {exc}") from None
        if not isinstance(raw, dict):
            raise InputError("the body must be a JSON object")
        return raw

    async def start(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        try:
            raw = await body(request)
            notes = raw.get("notes", "")
            if not isinstance(notes, str) or len(notes) > 10_000:
                raise InputError("notes must be text of at most 10000 characters")
            seconds = raw.get("seconds")
            if seconds is not None and (
                isinstance(seconds, bool) or not isinstance(seconds, int | float)
            ):
                raise InputError("seconds must be a number")
            info = TrialInfo(
                subject=str(raw.get("subject", "")),
                session=str(raw.get("session", "")),
                trial=str(raw.get("trial", "")),
                notes=notes,
            )
            info = acq.start_trial(info, None if seconds is None else float(seconds))
        except InputError as exc:
            return _error(409 if "being recorded" in str(exc) else 400, str(exc))
        return JSONResponse(info.to_dict(), status_code=201)

    async def stop(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        try:
            info = await asyncio.to_thread(acq.stop_trial)
        except InputError as exc:
            return _error(409, str(exc))
        return JSONResponse(info.to_dict())

    async def export(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        try:
            raw = await body(request)
            info = acq.store.load(request.path_params["tid"])
        except InputError as exc:
            return _error(404 if str(exc).startswith("no trial") else 400, str(exc))
        try:
            result = await asyncio.to_thread(
                export_trial,
                acq.store,
                info,
                raw.get("format", "c3d"),
                jobs.rig_for(info),
                lab.path,
                jobs.result(info),
            )
        except InputError as exc:
            return _error(409 if "being recorded" in str(exc) else 400, str(exc))
        except Exception as exc:  # a numerics error, told to the page
            return _error(422, f"export failed: {exc}")
        return JSONResponse(result)

    async def process(request: Request) -> Response:
        if (denied := await guard(request)) is not None:
            return denied
        try:
            info = acq.store.load(request.path_params["tid"])
        except InputError as exc:
            return _error(404 if str(exc).startswith("no trial") else 400, str(exc))
        if request.method == "GET":
            job = jobs.job(info.id)
            if job is None:
                return _error(404, f"trial {info.id} was not processed by this console")
            return JSONResponse(job)
        try:
            jobs.submit(info)
        except InputError as exc:
            return _error(409 if "being" in str(exc) else 400, str(exc))
        return JSONResponse(jobs.job(info.id), status_code=202)

    async def live(ws: WebSocket) -> None:
        if not allowed(token_of(ws)):
            await ws.close(code=4401)
            return
        await ws.accept()
        period = 1.0 / LIVE_HZ
        due = time.monotonic()
        slow_due, slow = 0.0, 0
        try:
            while True:
                now = time.monotonic()
                slow_text = ""
                if now >= slow_due:  # the tables and the 2-D views, at SLOW_HZ
                    views = {
                        name: {
                            "seq": v.seq,
                            "cameras": v.cameras,
                            "units": acq.view.units.get(name),
                        }
                        for name, v in list(acq.view.views.items())
                    }
                    slow += 1
                    slow_due = now + 1.0 / SLOW_HZ
                    slow_text = ", " + json.dumps(
                        {"slow": slow, "status": acq.status(), "devices": acq.devices(),
                         "views": views}
                    )[1:-1]  # fmt: skip
                fast = json.dumps({"t": time.time(), "markers": acq.markers.snapshot()})
                await ws.send_text(f"{fast[:-1]}{slow_text}}}")
                # on a fixed grid of 1 / LIVE_HZ (a late message does not delay the next)
                due = max(due + period, time.monotonic() - period)
                await asyncio.sleep(max(0.0, due - time.monotonic()))
        except (WebSocketDisconnect, RuntimeError, OSError):
            return

    routes = [
        Route("/", index),
        Route("/api/status", status),
        Route("/api/devices", devices),
        Route("/api/devices/{name}/reconnect", reconnect, methods=["POST"]),
        Route("/api/devices/{name}/configure", configure, methods=["POST"]),
        Route("/api/health", link_health),
        Route("/api/calibration", calibration),
        Route("/api/calibration/figure", calibration),
        Route("/api/calibration/{step}", calibration, methods=["POST"]),
        Route("/api/trials", trials),
        Route("/api/trials/start", start, methods=["POST"]),
        Route("/api/trials/stop", stop, methods=["POST"]),
        Route("/api/trials/{tid}/export", export, methods=["POST"]),
        Route("/api/trials/{tid}/process", process, methods=["GET", "POST"]),
        WebSocketRoute("/api/live", live),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    app = Starlette(routes=routes)
    # what the server ends after serving: the health sampler, the processing worker
    app.state.closers = [health.close, jobs.close]
    return app
