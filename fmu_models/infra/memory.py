"""How much memory the process may use: the one place every size cap of the project
(recordings, batches, campaigns, simulations) is derived from."""
from __future__ import annotations

from ..errors import ResourceError

__all__ = ["MEMORY_FRACTION", "available_memory", "check_fits"]

#: Fraction of the available memory one allocation may take before it is refused.
MEMORY_FRACTION = 0.5


def available_memory() -> int:
    """Bytes of memory available to this process (Linux: MemAvailable; elsewhere a
    conservative 2 GiB)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 2 * 1024**3


def check_fits(n_bytes: float, what: str, advice: str = "") -> None:
    """Refuse (ResourceError) an allocation of ``n_bytes`` for ``what`` that would take more
    than :data:`MEMORY_FRACTION` of the available memory; the message gives the numbers
    and ``advice``."""
    avail = available_memory()
    if n_bytes > MEMORY_FRACTION * avail:
        raise ResourceError(f"{what} needs {n_bytes / 2**30:.2f} GiB, more than {MEMORY_FRACTION:.0%} of the "
                            f"{avail / 2**30:.2f} GiB available" + (f"; {advice}" if advice else ""))
