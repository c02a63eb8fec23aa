"""``spotlab devices``: serial ports on this machine and the devices that answer on them."""

from __future__ import annotations

import argparse
import inspect
import json
import tempfile
from pathlib import Path
from typing import Any

from serial.tools import list_ports

from spotlab.console.errors import CommandError
from spotlab.drivers import available_families, load_driver
from spotlab.io.lab_file import LabFileError, load_lab

BY_ID = Path("/dev/serial/by-id")
SPOTLAB_LINKS = Path("/dev/spotlab")
#: Folders where running ``spotlab sim --pty`` simulators keep their port links.
SIM_LINK_GLOB = "spotlab-sim-*"


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "devices",
        help="list serial ports and, with --probe, the devices that answer on them",
        description="List serial ports (with their stable /dev/serial/by-id and /dev/spotlab "
        "links). With --probe, ask every driver family to detect its devices; probing sends "
        "a reset and a version query to each port, so leave it off while another program "
        "uses a port.",
    )
    p.add_argument("--probe", action="store_true", help="ask each driver family to detect devices")
    p.add_argument(
        "--lab",
        type=Path,
        metavar="LAB.toml",
        help="with --probe: also probe the network devices of this lab file (qualisys "
        "HOST[:PORT]); QTM is always looked for at 127.0.0.1:22223 and at $SPOTLAB_QTM",
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=run)


def _stable_links() -> dict[str, list[str]]:
    """Map of real device path -> stable symlinks pointing at it."""
    links: dict[str, list[str]] = {}
    for folder in (SPOTLAB_LINKS, BY_ID):
        if not folder.is_dir():
            continue
        for link in sorted(folder.iterdir()):
            try:
                links.setdefault(str(link.resolve()), []).append(str(link))
            except OSError:
                continue
    return links


def list_serial_ports() -> list[dict[str, Any]]:
    """Serial ports as dictionaries: device, stable links, USB ids, serial number, description."""
    links = _stable_links()
    ports = []
    for info in sorted(list_ports.comports(), key=lambda p: p.device):
        ports.append(
            {
                "device": info.device,
                "links": links.get(str(Path(info.device).resolve()), []),
                "vid": f"{info.vid:04x}" if info.vid is not None else None,
                "pid": f"{info.pid:04x}" if info.pid is not None else None,
                "serial_number": info.serial_number,
                "description": info.description,
            }
        )
    return ports


def simulator_ports() -> list[dict[str, Any]]:
    """Ports of running ``spotlab sim --pty`` simulators: the links they keep under
    ``TMPDIR/spotlab-sim-*/NAME``, while the pseudo-terminal they point at exists."""
    ports = []
    for link in sorted(Path(tempfile.gettempdir()).glob(f"{SIM_LINK_GLOB}/*")):
        try:
            target = link.resolve(strict=True)
        except (OSError, RuntimeError):
            continue  # a simulator that stopped, or a link being replaced
        if not link.is_symlink() or not str(target).startswith("/dev/"):
            continue
        ports.append(
            {
                "device": str(link),
                "links": [str(target)],
                "vid": None,
                "pid": None,
                "serial_number": None,
                "description": f"spotlab simulator ({link.name}, pseudo-terminal)",
            }
        )
    return ports


def _probe_ports(simulators: list[dict[str, Any]]) -> list[str]:
    """Serial ports with hardware behind them, then the simulators' links."""
    hardware = [p.device for p in list_ports.comports() if p.hwid and p.hwid != "n/a"]
    return hardware + [p["device"] for p in simulators]


def _lab_addresses(path: Path | None) -> dict[str, list[str]]:
    """Network addresses of a lab file's devices, by family (none without a lab file)."""
    if path is None:
        return {}
    try:
        lab = load_lab(path)
    except LabFileError as exc:
        raise CommandError(str(exc)) from None
    out: dict[str, list[str]] = {}
    for dev in lab.devices:
        out.setdefault(dev.family, []).append(dev.port)
    return out


def run(args: argparse.Namespace) -> int:
    simulators = simulator_ports()
    result: dict[str, Any] = {"serial_ports": list_serial_ports() + simulators, "devices": []}
    if args.probe:
        ports = _probe_ports(simulators)
        addresses = _lab_addresses(args.lab)
        for family in available_families():
            detect = load_driver(family).detect
            params = inspect.signature(detect).parameters
            if "ports" in params:
                found = detect(ports)
            elif "addresses" in params:
                found = detect(addresses.get(family, []))
            else:
                found = detect()
            for dev in found:
                result["devices"].append(
                    {
                        "family": dev.family,
                        "port": dev.port,
                        "description": dev.description,
                        "serial_number": dev.serial_number,
                        **({"extra": dev.extra} if dev.extra else {}),
                    }
                )
    if args.json:
        print(json.dumps(result))
        return 0
    if not result["serial_ports"]:
        print("no serial ports found")
    for port in result["serial_ports"]:
        ids = f" [{port['vid']}:{port['pid']}]" if port["vid"] else ""
        print(f"{port['device']}{ids} {port['description'] or ''}".rstrip())
        for link in port["links"]:
            print(f"    {link}")
    if args.probe:
        if not result["devices"]:
            print("no device answered")
        for dev in result["devices"]:
            print(f"{dev['family']} at {dev['port']}: {dev['description']}")
    return 0
