"""How much memory the process may use: the one place every size cap of the project
(recordings, batches, campaigns, simulations) is derived from."""
from __future__ import annotations

import contextlib
from pathlib import Path

from ..errors import ResourceError

__all__ = ["MEMORY_FRACTION", "available_memory", "check_fits"]

#: Fraction of the available memory one allocation may take before it is refused.
MEMORY_FRACTION = 0.5


def _system_available() -> int:
    """The machine's available memory (Linux: MemAvailable; elsewhere a conservative 2 GiB)."""
    with contextlib.suppress(OSError, ValueError, IndexError), open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 2 * 1024**3


def _process_limits() -> list[int]:
    """What the process may still take under its limits: the address-space limit (``ulimit
    -v``) less what it maps, and a cgroup v2 memory limit less the group's usage."""
    out = []
    with contextlib.suppress(ImportError, OSError, ValueError, IndexError):
        import resource

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            mapped = int(Path("/proc/self/statm").read_text().split()[0]) * resource.getpagesize()
            out.append(max(soft - mapped, 0))
    with contextlib.suppress(OSError, ValueError):
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit != "max":
            out.append(max(int(limit) - int(Path("/sys/fs/cgroup/memory.current").read_text()), 0))
    return out


def available_memory() -> int:
    """Bytes of memory available to this process: the machine's available memory, or less
    where the process's own limits (``ulimit -v``, a cgroup's memory limit) leave less."""
    return min([_system_available(), *_process_limits()])


def check_fits(n_bytes: float, what: str, advice: str = "") -> None:
    """Refuse (ResourceError) an allocation of ``n_bytes`` for ``what`` that would take more
    than :data:`MEMORY_FRACTION` of the available memory; the message gives the numbers
    and ``advice``."""
    avail = available_memory()
    if n_bytes > MEMORY_FRACTION * avail:
        raise ResourceError(f"{what} needs {n_bytes / 2**30:.2f} GiB, more than {MEMORY_FRACTION:.0%} of the "
                            f"{avail / 2**30:.2f} GiB available" + (f"; {advice}" if advice else ""))
