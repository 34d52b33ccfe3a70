"""Opening FMU files safely: a checked zip, bounded extraction into a private temporary
folder, one named :class:`~fmu_models.errors.FMUError` for a bad file, no leftovers."""
from __future__ import annotations

import shutil
import tempfile
import weakref
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

from fmu_models.errors import FMUError

from ..core import crash_guard

__all__ = ["MAX_FILES", "MAX_UNPACKED_BYTES", "Extraction", "FMUArchive", "read_archive", "read_description"]

#: Largest total unpacked size of an FMU [bytes].
MAX_UNPACKED_BYTES = 1 << 30
#: Largest number of files in an FMU.
MAX_FILES = 20_000


@contextmanager
def _checked_zip(path: Path, max_bytes: int, max_files: int, required: str = "modelDescription.xml",
                 label: str = "FMU") -> Iterator[zipfile.ZipFile]:
    """The archive at ``path`` opened: a zip within the limits, safe member paths, ``required`` in it."""
    if not path.exists():
        raise FMUError(f"no {label} file at {path}")
    if path.is_dir():
        raise FMUError(f"{path} is a folder, not an .{label.lower()} file (an {label} is a zip archive)")
    try:
        z = zipfile.ZipFile(path)
    except zipfile.BadZipFile:
        raise FMUError(f"{path} is not an {label}: not a zip archive (damaged or wrong file)") from None
    except OSError as e:
        raise FMUError(f"cannot read {path}: {e.strerror or e}") from None
    with z:
        infos = z.infolist()
        if len(infos) > max_files:
            raise FMUError(f"{path.name} holds {len(infos)} files, more than the limit of {max_files}")
        total = sum(i.file_size for i in infos)
        if total > max_bytes:
            raise FMUError(f"{path.name} would unpack to {total / 2**20:.0f} MiB, more than the limit of "
                           f"{max_bytes / 2**20:.0f} MiB")
        for i in infos:
            name = i.filename
            if name.startswith(("/", "\\")) or ".." in Path(name).parts or ":" in name.split("/")[0]:
                raise FMUError(f"{path.name} contains the unsafe path {name!r}")
        if required not in z.namelist():
            raise FMUError(f"{path.name} is not an {label}: it has no {required}")
        yield z


def read_description(path, max_bytes: int = MAX_UNPACKED_BYTES, max_files: int = MAX_FILES):
    """fmpy's ``ModelDescription`` of the FMU at ``path``, checked (at most ``max_bytes``
    unpacked, ``max_files`` files).

    Raises
    ------
    FMUError
        Missing file, a folder, not a zip, too large, too many files, unsafe member paths,
        no or unparsable ``modelDescription.xml`` (the message says which).
    """
    return read_archive(path, max_bytes, max_files).md


@dataclass
class FMUArchive:
    """An FMU file checked and read by :func:`read_archive`.

    Attributes
    ----------
    md : fmpy ModelDescription
    members : frozenset of str
        The names of the files it holds.
    xml : bytes
        Its ``modelDescription.xml``.
    """

    md: object
    members: frozenset
    xml: bytes

    @cached_property
    def root(self):
        """The XML's root element (no entities, no network), for what fmpy leaves unread."""
        from lxml import etree

        return etree.fromstring(self.xml, etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False))


def read_archive(path, max_bytes: int = MAX_UNPACKED_BYTES, max_files: int = MAX_FILES) -> FMUArchive:
    """The FMU at ``path`` (at most ``max_bytes`` unpacked, ``max_files`` files) checked as
    :func:`read_description` does, with its files' names and XML."""
    from fmpy import read_model_description

    path = Path(path)
    with _checked_zip(path, max_bytes, max_files) as z:
        try:
            z.testzip()
        except (zipfile.BadZipFile, OSError, EOFError) as e:
            raise FMUError(f"{path.name} is damaged: {e}") from None
        try:
            md = read_model_description(str(path), validate=False)
        except Exception as e:  # noqa: BLE001 - lxml, attrs and fmpy raise a variety of types for bad XML
            first = str(e).splitlines()[0] if str(e) else type(e).__name__
            raise FMUError(f"{path.name}: modelDescription.xml is not a valid FMI model description: "
                           f"{first}") from None
        archive = FMUArchive(md, frozenset(z.namelist()), z.read("modelDescription.xml"))   # read by fmpy: readable
    missing = {v.name: v for v in md.modelVariables if str(md.fmiVersion).startswith("3")
               and v.type.startswith(("Int", "UInt")) and v.min is None and v.max is None}
    for el in archive.root.iterfind("ModelVariables/*") if missing else ():     # fmpy leaves them None
        v = missing.get(el.get("name"))
        if v is not None:
            v.min, v.max = el.get("min"), el.get("max")
    return archive


def _remove(directory: str) -> None:
    shutil.rmtree(directory, True)
    crash_guard.temp_folder_removed(directory)


class Extraction:
    """An FMU (or SSP) unpacked into a private temporary folder, removed by :meth:`~.Extraction.close`.

    Parameters
    ----------
    path : path
        The ``.fmu`` file.
    max_bytes, max_files : int
        Limits on the total unpacked size [bytes] (enforced while unpacking too) and the number of files.
    required : str
        The member the archive must hold (default ``modelDescription.xml``).
    label : str
        What the archive is, in messages (default ``"FMU"``).

    Attributes
    ----------
    directory : str
        The folder (exists until :meth:`close`).
    """

    @classmethod
    def existing(cls, directory: str) -> Extraction:
        """An FMU another owner unpacked into ``directory``: used, never removed."""
        self = cls.__new__(cls)
        self.directory = directory
        self._finalizer = weakref.finalize(self, lambda: None)
        return self

    def __init__(self, path, max_bytes: int = MAX_UNPACKED_BYTES, max_files: int = MAX_FILES,
                 required: str = "modelDescription.xml", label: str = "FMU"):
        path = Path(path)
        self.directory = tempfile.mkdtemp(prefix=f"pendulum_cosim_{label.lower()}_")
        self._finalizer = weakref.finalize(self, _remove, self.directory)
        crash_guard.temp_folder_made(self.directory)      # removed by the salvage if an FMU crashes
        try:
            with _checked_zip(path, max_bytes, max_files, required, label) as z:
                written = 0
                for info in z.infolist():
                    target = Path(self.directory, info.filename)
                    (target if info.is_dir() else target.parent).mkdir(parents=True, exist_ok=True)
                    if info.is_dir():
                        continue
                    with z.open(info) as src, open(target, "wb") as dst:
                        while chunk := src.read(1 << 20):
                            written += len(chunk)
                            if written > max_bytes:
                                raise FMUError(f"{path.name} unpacks to more than {max_bytes / 2**20:.0f} MiB "
                                               "(its declared sizes are wrong)")
                            dst.write(chunk)
        except (zipfile.BadZipFile, OSError, EOFError) as e:
            self.close()
            raise FMUError(f"cannot unpack {path.name}: {e}") from None
        except BaseException:          # FMUError and Ctrl-C too
            self.close()
            raise

    def close(self) -> None:
        """Remove the folder (safe to call twice)."""
        self._finalizer()

    @property
    def closed(self) -> bool:
        """True once the folder is removed."""
        return not self._finalizer.alive
