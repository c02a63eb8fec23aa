"""Workers, progress, the JSON summary, and the saved failure with its replay.

Prints progress to stderr and one JSON line at the end. Exit code 1 when an
unexpected exception or an invariant violation happened; the first failing
input (with the inputs before it in the same decoder run) is saved as JSON and
can be replayed with ``--replay FILE``.
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import os
import random
import sys
import tempfile
import time
import traceback
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import __doc__ as package_doc
from .decoder_run import DecoderRun, Step
from .invariants import Failure, UnexpectedError
from .mutations import make_cuts, make_input
from .replies import check_reply, make_reply
from .streams import LAYOUTS, WEIGHTS, Corpus

#: Counters of the decoders summed into ``decoded``.
TOTALS = ("frames", "lost_frames", "crc_errors", "resyncs", "duplicates", "gaps")
#: Tally fields summed over the workers, in the order the summary gives them.
SUMMED = ("reply_inputs", "bytes", "unexpected_exceptions", "invariant_violations")


@dataclass
class Tally:
    """What one worker did and found."""

    inputs: int = 0
    reply_inputs: int = 0
    bytes: int = 0
    unexpected_exceptions: int = 0
    invariant_violations: int = 0
    failures: list[str] = field(default_factory=list)
    failure_file: str | None = None
    totals: Counter[str] = field(default_factory=Counter)

    def add_run(self, run: DecoderRun) -> None:
        """Add the counters of a finished run's three decoders to ``totals``."""
        for checked in run.decoders:
            dec = checked.dec
            self.totals.update({name: getattr(dec.stats, name) for name in TOTALS})
            self.totals.update(restarts=dec.restarts, config_mismatches=dec.config_mismatches)

    def record_failure(self, exc: Exception, record: dict[str, Any], path: Path) -> None:
        """Count a failure; save the first one (``record`` and the traceback) to ``path``."""
        if isinstance(exc, UnexpectedError):
            self.unexpected_exceptions += 1
            cause = exc.__cause__
            detail = "".join(traceback.format_exception(cause)) if cause else str(exc)
        else:
            self.invariant_violations += 1
            detail = "".join(traceback.format_exception(exc))
        if len(self.failures) < 5:
            self.failures.append(str(exc))
        if self.failure_file is None:
            record = {**record, "message": str(exc), "traceback": detail}
            path.write_text(json.dumps(record, indent=1))
            self.failure_file = str(path)


def worker(seed: int, n_inputs: int, seconds: float | None, failure_dir: str, wid: int) -> Tally:
    logging.disable(logging.CRITICAL)  # decoders log config mismatches, replies log WARNxx
    rng = random.Random(seed)
    corpus = Corpus(rng)
    tally = Tally()
    failure_path = Path(failure_dir) / f"fuzz_selspot-failure-seed{seed}.json"
    t0 = time.monotonic()
    deadline = None if seconds is None else t0 + seconds
    next_report = t0 + 10.0
    run: DecoderRun | None = None
    left = 0
    while tally.inputs < n_inputs:
        now = time.monotonic()
        if deadline is not None and now >= deadline:
            break
        if now >= next_report:
            next_report = now + 10.0
            print(
                f"[worker {wid}] {tally.inputs}/{n_inputs} inputs, "
                f"{tally.inputs / (now - t0):.0f}/s, unexpected {tally.unexpected_exceptions}, "
                f"violations {tally.invariant_violations}",
                file=sys.stderr,
                flush=True,
            )
        if run is None or left == 0:
            if run is not None:
                tally.add_run(run)
            run = DecoderRun(rng.choices(LAYOUTS, WEIGHTS)[0])
            left = rng.randint(1, 64)
        left -= 1
        layout = run.layout
        if rng.random() < 0.02:  # refresh the corpus as the run goes
            corpus.refresh(rng, layout)
        data = make_input(rng, rng.choice(corpus.by_layout[layout]), corpus.all)
        cuts = make_cuts(rng, len(data), run.whole.dec.frame_bytes)
        st = Step(data, cuts, mark_before=rng.random() < 0.3, many=rng.random() < 0.7)
        if rng.random() < 0.05 and len(cuts) > 1:
            st.mid = [(rng.randrange(len(cuts)), rng.choice(["flush", "mark"]))]
        tally.inputs += 1
        tally.bytes += len(data)
        try:
            events = run.step(st)
        except (Failure, UnexpectedError) as exc:
            record: dict[str, Any] = {"kind": "decoder", "layout": list(layout)}
            record["steps"] = [s.to_json() for s in run.steps]
            tally.record_failure(exc, record, failure_path)
            run, left = None, 0
            continue
        line, prefix = make_reply(rng)
        for payload, pre in [(line, prefix), *((e, None) for e in events[:4])]:
            tally.reply_inputs += 1
            try:
                check_reply(payload, pre)
            except (Failure, UnexpectedError) as exc:
                record = {"kind": "reply", "line": payload.hex(), "prefix": pre}
                tally.record_failure(exc, record, failure_path)
    if run is not None:
        tally.add_run(run)
    return tally


def replay(path: Path) -> int:
    logging.disable(logging.CRITICAL)
    record = json.loads(path.read_text())
    try:
        if record["kind"] == "reply":
            check_reply(bytes.fromhex(record["line"]), record["prefix"])
        else:
            cams, leds, slot = record["layout"]
            run = DecoderRun((cams, leds, slot))
            for d in record["steps"]:
                run.step(Step.from_json(d))
    except (Failure, UnexpectedError) as exc:
        cause = exc.__cause__ or exc
        traceback.print_exception(cause)
        return 1
    print("replayed without failure", file=sys.stderr)
    return 0


def summarize(
    tallies: list[Tally], requested: int, elapsed: float, seeds: list[int]
) -> dict[str, Any]:
    """The JSON summary of all workers."""
    inputs = sum(t.inputs for t in tallies)
    summary: dict[str, Any] = {"benchmark": "fuzz_selspot", "inputs": inputs}
    summary["inputs_requested"] = requested
    summary.update({name: sum(getattr(t, name) for t in tallies) for name in SUMMED})
    summary["seconds"] = round(elapsed, 1)
    summary["inputs_per_s"] = round(inputs / elapsed) if elapsed > 0 else None
    summary["workers"] = len(seeds)
    summary["seeds"] = seeds
    decoded: Counter[str] = Counter()
    for t in tallies:
        decoded.update(t.totals)  # update, unlike +, keeps the counters that stayed 0
    summary["decoded"] = dict(decoded)
    failures = [f for t in tallies for f in t.failures]
    if failures:
        summary["failures"] = failures[:5]
        summary["failure_files"] = [t.failure_file for t in tallies if t.failure_file]
    return summary


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=(package_doc or "").splitlines()[0])
    parser.add_argument("--inputs", type=int, default=1_000_000, help="mutated SPX streams")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--seconds", type=float, help="stop after this long (a cap)")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument(
        "--failure-dir", default=tempfile.gettempdir(), help="where the first failure is saved"
    )
    parser.add_argument("--replay", type=Path, help="re-run a saved failure and show it")
    args = parser.parse_args(argv)
    if args.replay:
        return replay(args.replay)
    workers = max(1, args.workers)
    share = [args.inputs // workers + (k < args.inputs % workers) for k in range(workers)]
    seeds = [args.seed * 1000 + k for k in range(workers)]
    t0 = time.monotonic()
    jobs = [(seeds[k], share[k], args.seconds, args.failure_dir, k) for k in range(workers)]
    if workers == 1:
        tallies = [worker(*jobs[0])]
    else:
        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            tallies = pool.starmap(worker, jobs)
    summary = summarize(tallies, args.inputs, time.monotonic() - t0, seeds)
    print(json.dumps(summary), flush=True)
    bad = summary["unexpected_exceptions"] or summary["invariant_violations"]
    return 1 if bad else 0
