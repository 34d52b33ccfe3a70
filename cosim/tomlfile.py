"""Reading TOML input (scenario files, settings files, ``--set`` values) within limits: a
size cap checked before the file is read, a nesting cap checked before it is parsed (the
standard library's parser recurses once per level and would end in RecursionError), and
every failure a :class:`~fmu_models.errors.ConfigurationError` naming the file.
"""
from __future__ import annotations

import itertools
import re
import tomllib
from pathlib import Path

from fmu_models.errors import ConfigurationError

__all__ = ["MAX_TOML_BYTES", "MAX_TOML_DEPTH", "loads", "read"]

#: The largest TOML input read (a scenario with a 100 000-row inline table is 10 MiB).
MAX_TOML_BYTES = 16 * 2**20
#: The deepest nesting of arrays and inline tables accepted.
MAX_TOML_DEPTH = 64


#: Strings (an escape skipped in basic ones; an unclosed one runs to the end) and comments.
_NOT_NESTING = re.compile(r'"(?:\\[\s\S]?|[^"\\])*(?:"|\Z)|\'[^\']*(?:\'|\Z)|#[^\n]*')


def _depth(text: str) -> int:
    """The deepest nesting of ``[``/``{`` outside strings and comments (a scan, no parse)."""
    brackets = re.findall(r"[][{}]", _NOT_NESTING.sub("", text))
    return max(itertools.accumulate((1 if ch in "[{" else -1 for ch in brackets), initial=0))


def loads(text: str, what: str) -> dict:
    """Parse TOML ``text`` (``what`` names it in messages)."""
    if len(text) > MAX_TOML_BYTES:
        raise ConfigurationError(f"{what}: {len(text) / 2**20:.1f} MiB of TOML, more than "
                                 f"{MAX_TOML_BYTES // 2**20} MiB")
    if _depth(text) > MAX_TOML_DEPTH:
        raise ConfigurationError(f"{what}: arrays or tables nested more than {MAX_TOML_DEPTH} deep")
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigurationError(f"{what}: not valid TOML: {e}") from None
    except RecursionError:
        raise ConfigurationError(f"{what}: nested too deep to parse") from None


def read(path, what: str = "file") -> dict:
    """Read and parse the TOML file ``path`` (``what``: "scenario file", "settings file"),
    refusing a missing file, a folder, an oversized or binary file by name."""
    path = Path(path)
    if path.is_dir():
        raise ConfigurationError(f"{path} is a folder, not a {what} (.toml)")
    try:
        size = path.stat().st_size
        if size > MAX_TOML_BYTES:
            raise ConfigurationError(f"{what} {path}: {size / 2**20:.1f} MiB, more than "
                                     f"{MAX_TOML_BYTES // 2**20} MiB of TOML")
        with open(path, "rb") as f:
            data = f.read(MAX_TOML_BYTES + 1)
    except FileNotFoundError:
        raise ConfigurationError(f"no {what} {path}") from None
    except OSError as e:
        raise ConfigurationError(f"cannot read the {what} {path}: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigurationError(f"{what} {path} is not UTF-8 text (byte {e.start}): not a TOML file") from None
    return loads(text, f"{what} {path}")
