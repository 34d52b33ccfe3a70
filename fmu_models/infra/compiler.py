"""The C compiler, run safely: found or named, interruptible, leaving nothing behind (its
process group ended and its temporary files removed, whatever stops it)."""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from ..errors import BuildError, CompilerNotFoundError
from .files import private_tempdir

__all__ = ["find_compiler", "run_compiler"]


def find_compiler() -> str:
    """Return the C compiler to use: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH.

    Raises
    ------
    CompilerNotFoundError
        None is found (the message says what to install).
    """
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for cand in candidates:
        if path := shutil.which(cand):
            return path
    raise CompilerNotFoundError(
        "no C compiler found (looked for " + ", ".join(candidates) + "). Building an FMU "
        "compiles generated C code: install gcc (Debian/Ubuntu: 'apt-get install gcc', "
        "Fedora: 'dnf install gcc', macOS: 'xcode-select --install') or set CC.")


def _end_group(proc: subprocess.Popen) -> None:
    """Terminate, then kill, the process group of ``proc`` and reap it."""
    for sig, wait in ((signal.SIGTERM, 2.0), (signal.SIGKILL, 5.0)):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=wait)
            return


def run_compiler(cmd: Sequence[str], what: str, cwd: str | Path | None = None, timeout: float = 600.0,
                 cancel: threading.Event | None = None) -> str:
    """Run the compiler command ``cmd`` in its own process group with ``TMPDIR`` a private folder;
    returns its output. Interrupted or failing, the group is ended and its temporary files removed
    before the exception goes on.

    Parameters
    ----------
    cmd, what, cwd
        The compiler and its arguments; what it builds (for messages); working directory (default: the current one).
    timeout, cancel
        Longest time [s] the compiler may take; an event another thread sets to end the compiler (the main
        thread on Ctrl-C while compilers run in worker threads), which then raises BuildError ("cancelled").

    Raises
    ------
    BuildError
        The compiler failed, timed out or could not be started; the message has its output.
    """
    with private_tempdir("pendulum_cosim_cc_") as tmp:
        env = {**os.environ, "TMPDIR": tmp, "TMP": tmp, "TEMP": tmp}
        try:
            proc = subprocess.Popen(list(cmd), cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, start_new_session=True)
        except OSError as e:
            raise BuildError(f"compiling {what}: cannot run the compiler {cmd[0]}: {e.strerror or e}") from None
        deadline = time.monotonic() + timeout
        try:
            while True:
                try:
                    out, _ = proc.communicate(timeout=min(0.2, max(deadline - time.monotonic(), 0.0)))
                    break
                except subprocess.TimeoutExpired:
                    if time.monotonic() >= deadline:
                        raise
                    if cancel is not None and cancel.is_set():
                        _end_group(proc)
                        raise BuildError(f"compiling {what}: cancelled") from None
        except subprocess.TimeoutExpired:
            _end_group(proc)
            raise BuildError(f"compiling {what}: the compiler did not finish in {timeout:g} s") from None
        except BaseException:
            _end_group(proc)
            raise
        if proc.returncode != 0:
            text = out.strip() or f"(the compiler printed nothing; exit status {proc.returncode})"
            raise BuildError(f"compiling {what} failed:\n{' '.join(map(str, cmd))}\n{text}")
        return out
