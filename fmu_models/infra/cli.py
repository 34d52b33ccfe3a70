"""The one error handler of the project's command lines (``pendulum-cosim`` and ``python -m fmu_models``):
what an error, Ctrl-C or SIGTERM becomes on the terminal and in the exit status."""
from __future__ import annotations

import sys
import warnings
import zipfile
from collections.abc import Callable

from ..errors import Interrupted, PendulumCosimError
from .interrupts import terminate_as_interrupt

__all__ = ["EXIT_ERROR", "EXIT_INTERRUPTED", "KNOWN_ERRORS", "one_line", "run_command"]

#: Exit statuses of a refused command (2) and of an interrupted one (130, as a shell reports SIGINT).
EXIT_ERROR, EXIT_INTERRUPTED = 2, 130


try:
    from lxml.etree import XMLSyntaxError  # optional here: fmpy reads XML with it
    _XML_ERRORS: tuple[type[BaseException], ...] = (XMLSyntaxError,)
except ImportError:
    _XML_ERRORS = ()
#: The exceptions printed as one line (the project's family, bad zip and XML, OS errors).
KNOWN_ERRORS = (PendulumCosimError, zipfile.BadZipFile, OSError, UnicodeDecodeError, *_XML_ERRORS)


def one_line(error: BaseException) -> str:
    """The message of ``error`` on one line (its type name if it has none)."""
    return " ".join(str(error).split()) or type(error).__name__


def run_command(command: Callable[[], int], debug: bool = False, cleanup: Callable[[], None] | None = None,
                interrupted: str = "interrupted (Ctrl-C or SIGTERM)") -> int:
    """Run ``command()`` with SIGTERM as Ctrl-C and return its exit status, or the status of its failure.

    An error of the project's family or a known library or system error (:data:`KNOWN_ERRORS`)
    prints one line ``error: ...`` and returns :data:`EXIT_ERROR`; Ctrl-C and SIGTERM print one
    line and return :data:`EXIT_INTERRUPTED`, also when a native extension wrapped the
    KeyboardInterrupt in a SystemError (CasADi's callbacks do). Warnings print as one line
    ``warning: ...`` each.

    Parameters
    ----------
    command, cleanup
        The work of the command line, returning its exit status (0 on success); what is called on
        every failure before the message is printed.
    debug, interrupted
        Let errors through with their traceback; the line printed for Ctrl-C or SIGTERM.
    """
    try:
        with terminate_as_interrupt(), warnings.catch_warnings():
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning
            return command()
    except (KeyboardInterrupt, SystemError, *KNOWN_ERRORS) as e:
        line, status = f"error: {one_line(e)}", EXIT_ERROR
        if isinstance(e, (KeyboardInterrupt, SystemError)):      # a native extension may wrap Ctrl-C
            if not isinstance(e, KeyboardInterrupt) and not isinstance(e.__cause__ or e.__context__, KeyboardInterrupt):
                raise
            line, status = interrupted, EXIT_INTERRUPTED
        elif isinstance(e, Interrupted):
            line, status = f"interrupted: {one_line(e)}", EXIT_INTERRUPTED
        if debug:
            raise
        if cleanup is not None:
            cleanup()
        print(line, file=sys.stderr)
        return status


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {one_line(message)}", file=sys.stderr if file is None else file)
