"""Resource guards and progress lines shared by the commands.

* :func:`require_memory` compares an estimate of what a run will allocate with the memory
  available now (``psutil``) and raises a one-line :class:`~lcc_synth.errors.ConfigError`
  naming the field that makes it large, BEFORE anything is allocated.
* :func:`progress` prints one line on stderr (``lcc-synth: synthesis: ...``) for long work
  that has no progress bar (synthesis stages, LMI solves, sparsity sweep); commands switch it
  off with ``--no-progress`` through :func:`set_progress`.
"""

from __future__ import annotations

import sys

from lcc_synth.errors import ConfigError

__all__ = ["available_memory", "format_bytes", "require_memory", "progress", "set_progress"]

#: fraction of the available memory a single run may plan to use
MEMORY_FRACTION = 0.8

_PROGRESS = {"enabled": False}


def available_memory() -> int:
    """Bytes of memory available now (``psutil``; ``/proc/meminfo`` as a fallback)."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # pragma: no cover - psutil is a dependency
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
        return 1 << 62


def format_bytes(n: float) -> str:
    """``n`` bytes as ``"1.2 GiB"``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def require_memory(field: str, needed: float, what: str, hint: str = "") -> None:
    """Raise :class:`ConfigError` for ``field`` when ``needed`` bytes cannot fit.

    ``what`` says what the estimate counts (e.g. ``"6000001 steps x 12 vehicles x 1
    scenario"``); ``hint`` what to change.
    """
    avail = available_memory()
    if needed > MEMORY_FRACTION * avail:
        raise ConfigError(
            field,
            f"the run needs about {format_bytes(needed)} of memory ({what}) but only "
            f"{format_bytes(avail)} is available{'; ' + hint if hint else ''}",
        )


def set_progress(enabled: bool) -> None:
    """Switch the progress lines of :func:`progress` on or off (off by default)."""
    _PROGRESS["enabled"] = bool(enabled)


def progress(message: str) -> None:
    """One progress line on stderr when enabled (flushed at once)."""
    if _PROGRESS["enabled"]:
        print(f"lcc-synth: {message}", file=sys.stderr, flush=True)
