"""The line of a stream's journalled link faults, as ``spotlab info`` and ``spotlab
record`` print it from the same recording summary."""

from __future__ import annotations

from typing import Any

__all__ = ["fault_line"]

USB_FAULTS = (("stall", "stalls"), ("timeout", "timeouts"), ("short", "short packets"),
              ("babble", "babble"))  # fmt: skip
"""WSX fault names in the journal (``error`` events' ``fault``) and how they are printed."""


def fault_line(stream: dict[str, Any]) -> str | None:
    """``USB faults: stalls 1, ...`` for a WSX stream of a summary, None for other families.

    Parameters
    ----------
    stream : dict
        One stream of :meth:`RecordingSummary.to_dict` (``family``, ``faults``,
        ``disconnections``, ``reconnects``).

    Returns
    -------
    str or None
        Every USB fault kind with its count (0 too), the unplugs (disconnections) and
        returns (reconnects), then any other fault the journal names.
    """
    if stream.get("family") != "wsx":
        return None
    faults = dict(stream.get("faults") or {})
    parts = [f"{label} {faults.pop(name, 0)}" for name, label in USB_FAULTS]
    parts.append(
        f"unplugged {stream.get('disconnections', 0)} (returned {stream.get('reconnects', 0)})"
    )
    parts += [f"{name} {n}" for name, n in sorted(faults.items())]
    return "USB faults: " + ", ".join(parts)
