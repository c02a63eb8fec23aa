"""Mutation fuzzing of every decoder and reader: only spotlab's documented errors may come out.

TARGETS.md: every decoder is fuzzed with >= 1 000 000 mutated inputs, and only the
documented protocol errors may be raised. The SPX decoder has its own frame-aware
fuzzer (``benchmarks/fuzz_selspot.py``); this one covers the rest with blind mutations
of valid inputs made here:

========  ==========================================================================
target    what is fed, and what counts as a documented outcome
========  ==========================================================================
tmr       TMR link bytes (a recording of the simulated timer) in random reads into
          :class:`~spotlab.drivers.timer.TimerDecoder`, then ``flush``: never raises
cen       CEN link bytes (the simulated hub, 2 cameras) into
          :class:`~spotlab.drivers.centroid.CentroidDecoder`: never raises
wsx       WSX bulk and interrupt bytes (a recording of the simulated hub: 2 position
          sensors, a stall and a short packet) in random reads into
          :class:`~spotlab.drivers.wsx.decoding.WsxDecoder`: never raises, blocks
          keep their shape and ``seq`` never goes back (:mod:`~spotlab.testing.fuzz_wsx`)
wsx-ctl   the simulated hub's EP 0 replies (information, set-up, status, factory
          calibration) through every parser the WSX driver uses on them:
          :class:`~spotlab.core.errors.ProtocolError` only
journal   a recording's file read with :class:`~spotlab.io.journal.JournalReader`:
          :class:`~spotlab.core.errors.SpotlabError` subclasses only
c3d       a C3D file (written by spotlab from a small trial) through
          :func:`~spotlab.io.read_c3d`: ``SpotlabError`` subclasses only
trc       a TRC file through :func:`~spotlab.io.read_trc`: likewise
rig       a rig TOML through :meth:`~spotlab.geometry.Rig.load`: likewise
model     a marker-model JSON through :meth:`MarkerModel.load`: likewise
========  ==========================================================================

Mutations: bit flips, byte replacements, inserted random bytes and tokens of the
format (sync words, ``[``, ``=``, ``"``, digits, NaN), deleted, repeated and swapped
ranges, truncation, splices of another input of the same target, and plain random
bytes. Anything else raised (``IndexError``, ``struct.error``, ``UnicodeDecodeError``,
a numpy error...) is a finding: counted, with the input kept for replay.
"""

from __future__ import annotations

import random
import tempfile
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spotlab.core.errors import SpotlabError
from spotlab.testing import fuzz_wsx

__all__ = ["TARGETS", "FuzzResult", "fuzz", "mutate"]

TOKENS = (
    b"\xa5\x5a", b"\xa5", b"\x5a", b"\r", b"\n", b"\x00", b"\xff\xff\xff\xff", b"[", b"]",
    b"=", b'"', b"{", b"}", b",", b"nan", b"-1", b"1e308", b"65535", b"SPJ", b"\t",
)  # fmt: skip


def mutate(rng: random.Random, data: bytes, other: bytes) -> bytes:
    """One input: ``data`` damaged 1-4 times (``other``: a second input to splice from)."""
    if rng.random() < 0.02:
        return rng.randbytes(rng.randint(0, 2 * len(data) + 1))
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        n = len(b)
        op = rng.randrange(9)
        i = rng.randrange(n + 1)
        if op == 0 and n:  # bit flips
            for _ in range(rng.randint(1, 8)):
                k = rng.randrange(n)
                b[k] ^= 1 << rng.randrange(8)
        elif op == 1 and n:  # bytes replaced
            k = rng.randint(1, 16)
            b[i : i + k] = rng.randbytes(len(b[i : i + k]))
        elif op == 2:  # random bytes inserted
            b[i:i] = rng.randbytes(rng.randint(1, 64))
        elif op == 3:  # a token inserted
            b[i:i] = rng.choice(TOKENS)
        elif op == 4:  # a range deleted
            del b[i : i + rng.randint(1, max(1, n // 8))]
        elif op == 5:  # a range repeated
            k = rng.randint(1, max(1, n // 8))
            b[i:i] = b[i : i + k]
        elif op == 6 and n > 2:  # two ranges swapped
            j = rng.randrange(n)
            k = rng.randint(1, max(1, n // 16))
            x, y = sorted((i, j))
            if x + k <= y:
                b[x : x + k], b[y : y + k] = b[y : y + k], b[x : x + k]
        elif op == 7:  # truncated
            del b[rng.randrange(n + 1) :]
        elif op == 8 and other:  # spliced with another input
            j = rng.randrange(len(other))
            b[i:] = other[j : j + rng.randint(1, len(other))]
    return bytes(b)


@dataclass
class FuzzResult:
    """What one target's run found.

    Attributes
    ----------
    target : str
        Its name.
    inputs : int
        Inputs fed.
    documented : int
        Inputs that ended in a documented spotlab error (readers; decoders never raise).
    findings : dict
        Undocumented exception type and where it was raised -> (count, first input).
    seconds : float
        Wall time.
    """

    target: str
    inputs: int = 0
    documented: int = 0
    findings: dict[str, tuple[int, bytes]] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def unexpected(self) -> int:
        """Inputs that raised anything else."""
        return sum(n for n, _ in self.findings.values())

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe summary (the findings by type, without the inputs)."""
        return {
            "target": self.target, "inputs": self.inputs, "documented_errors": self.documented,
            "unexpected": self.unexpected, "seconds": round(self.seconds, 2),
            "findings": {k: n for k, (n, _) in self.findings.items()},
        }  # fmt: skip


@dataclass(frozen=True)
class _Target:
    corpus: Callable[[Path], list[bytes]]
    make_run: Callable[[Path, list[bytes]], Callable[[bytes, random.Random], None]]


def _recorded(folder: Path, url: str, driver: str) -> tuple[dict[str, Any], bytes, Path]:
    """0.3 s recorded from an in-process simulator: (stream metadata, its RX bytes, journal)."""
    from spotlab.acquisition.recorder import Recorder
    from spotlab.acquisition.session import Session
    from spotlab.drivers.base import Driver
    from spotlab.drivers.centroid import CentroidDriver
    from spotlab.drivers.coda import CodaDriver
    from spotlab.drivers.timer import TimerDriver
    from spotlab.io._journal_format import RecordType
    from spotlab.io.journal import JournalReader

    journal = folder / f"{driver}.spj"
    device: Driver
    if driver == "timer":
        device = TimerDriver(url, rate_hz=100.0)
    elif driver == "coda":
        device = CodaDriver(url, markers=4, rate_hz=200.0)
    else:
        device = CentroidDriver(url, cameras=2, rate_hz=100.0)
    with Session([device], [Recorder(journal)], close_devices=True) as session:
        session.run_for(0.3)
    reader = JournalReader(journal)
    meta = next(iter(reader.streams.values()))
    rx = b"".join(r.payload for r in reader if r.type == RecordType.RX)
    return meta, rx, journal


def _stream_corpus(url: str, driver: str) -> Callable[[Path], list[bytes]]:
    def corpus(folder: Path) -> list[bytes]:
        meta, rx, _ = _recorded(folder, url, driver)
        (folder / f"{driver}.meta.json").write_text(__import__("json").dumps(meta))
        # Cut at a frame boundary near the middle too: two inputs to splice.
        return [rx, rx[len(rx) // 2 :]]

    return corpus


def _stream_run(
    driver: str,
) -> Callable[[Path, list[bytes]], Callable[[bytes, random.Random], None]]:
    def make_run(folder: Path, corpus: list[bytes]) -> Callable[[bytes, random.Random], None]:
        import json

        from spotlab.drivers.centroid import decoder_from_metadata as centroid_decoder
        from spotlab.drivers.coda import decoder_from_metadata as coda_decoder
        from spotlab.drivers.timer import decoder_from_metadata as timer_decoder

        meta = json.loads((folder / f"{driver}.meta.json").read_text())
        decoders: dict[str, Callable[[Any], Any]] = {"timer": timer_decoder, "coda": coda_decoder}
        decoder_for = decoders.get(driver, centroid_decoder)

        def run(data: bytes, rng: random.Random) -> None:
            decoder: Any = decoder_for(meta)
            pos = 0
            t = 0
            while pos < len(data):
                step = rng.choice((1, 7, 64, 512, 4096, 1 << 16))
                t += 1_000_000
                decoder.feed(data[pos : pos + step], t)
                pos += step
            decoder.flush()

        return run

    return make_run


def _file_run(
    suffix: str, read: Callable[[Path], object]
) -> Callable[[Path, list[bytes]], Callable[[bytes, random.Random], None]]:
    def make_run(folder: Path, corpus: list[bytes]) -> Callable[[bytes, random.Random], None]:
        path = folder / f"input{suffix}"

        def run(data: bytes, rng: random.Random) -> None:
            path.write_bytes(data)
            read(path)

        return run

    return make_run


def _journal_corpus(folder: Path) -> list[bytes]:
    _, _, journal = _recorded(folder, "sim://timer?rate=100", "timer")
    return [journal.read_bytes()]


def _read_journal(path: Path) -> None:
    from spotlab.io.journal import JournalReader

    reader = JournalReader(path)
    for _ in reader:
        pass


def _trial() -> Any:
    from spotlab.io import Trial

    t = np.arange(30) / 100.0
    cols = [
        np.stack([100 * np.sin(t + k), 50 * np.cos(t), 900 + 10 * k + 0 * t], 1) for k in range(4)
    ]
    points = np.stack(cols, 1)
    points[5, 2] = np.nan
    return Trial(points=points, labels=["LASI", "RASI", "LKNE", "RKNE"], point_rate=100.0)


def _c3d_corpus(folder: Path) -> list[bytes]:
    from spotlab.io import write_c3d

    write_c3d(folder / "a.c3d", _trial())
    return [(folder / "a.c3d").read_bytes()]


def _trc_corpus(folder: Path) -> list[bytes]:
    from spotlab.io import write_trc

    write_trc(folder / "a.trc", _trial())
    return [(folder / "a.trc").read_bytes()]


def _rig_corpus(folder: Path) -> list[bytes]:
    from spotlab.simulators.rigs import ring_rig

    ring_rig(2).save(folder / "rig.toml")
    return [(folder / "rig.toml").read_bytes()]


def _model_corpus(folder: Path) -> list[bytes]:
    from spotlab.reconstruction.identification import MarkerModel
    from spotlab.simulators.motions import RigidClusters

    motion = RigidClusters(n_markers=8, cluster_size=4, seed=1)
    t = np.arange(200) / 50.0
    X = np.stack([motion.sample(t, np.full(t.size, m)) for m in range(8)], 1)
    MarkerModel.infer(motion.labels, X).save(folder / "model.json")
    return [(folder / "model.json").read_bytes()]


def _rig_load(path: Path) -> None:
    from spotlab.geometry import Rig

    Rig.load(path)


def _model_load(path: Path) -> None:
    from spotlab.reconstruction.identification import MarkerModel

    MarkerModel.load(path)


def _c3d_read(path: Path) -> None:
    from spotlab.io import read_c3d

    read_c3d(path)


def _trc_read(path: Path) -> None:
    from spotlab.io import read_trc

    read_trc(path)


TARGETS: dict[str, _Target] = {
    "tmr": _Target(_stream_corpus("sim://timer?rate=100", "timer"), _stream_run("timer")),
    "cen": _Target(
        _stream_corpus("sim://centroid?cameras=2&markers=10&rate=100", "centroid"),
        _stream_run("centroid"),
    ),
    "csx": _Target(
        _stream_corpus("sim://coda?markers=4&rate=200&colour_rate=0.05&ghost_rate=0.05", "coda"),
        _stream_run("coda"),
    ),
    "wsx": _Target(fuzz_wsx.frames_corpus, fuzz_wsx.frames_run),
    "wsx-ctl": _Target(fuzz_wsx.control_corpus, fuzz_wsx.control_run),
    "journal": _Target(_journal_corpus, _file_run(".spj", _read_journal)),
    "c3d": _Target(_c3d_corpus, _file_run(".c3d", _c3d_read)),
    "trc": _Target(_trc_corpus, _file_run(".trc", _trc_read)),
    "rig": _Target(_rig_corpus, _file_run(".toml", _rig_load)),
    "model": _Target(_model_corpus, _file_run(".json", _model_load)),
}


def fuzz(target: str, inputs: int, *, seed: int = 0, seconds: float | None = None) -> FuzzResult:
    """Feed ``inputs`` mutated inputs to one target (or stop after ``seconds``).

    Raises
    ------
    KeyError
        For a target not in :data:`TARGETS`.
    """
    spec = TARGETS[target]
    rng = random.Random(seed)
    result = FuzzResult(target)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="spotlab-fuzz-") as tmp:
        folder = Path(tmp)
        corpus = spec.corpus(folder)
        run = spec.make_run(folder, corpus)
        for k in range(inputs):
            data = mutate(rng, rng.choice(corpus), rng.choice(corpus))
            result.inputs += 1
            try:
                with np.errstate(all="ignore"):
                    run(data, rng)
            except SpotlabError:
                result.documented += 1
            except Exception as exc:  # a finding, kept
                frame = traceback.extract_tb(exc.__traceback__)[-1]
                key = f"{type(exc).__name__} at {Path(frame.filename).name}:{frame.lineno}"
                n, first = result.findings.get(key, (0, data))
                result.findings[key] = (n + 1, first)
            if seconds is not None and k % 64 == 0 and time.perf_counter() - start > seconds:
                break
    result.seconds = time.perf_counter() - start
    return result
