"""Registries: the extension points of the project by name, filled where each thing is defined, and
the loading of plugins that register more (the user guide's page "Extending it" lists them)."""
from __future__ import annotations

import functools
import importlib
import importlib.util
import sys
import warnings
from collections.abc import Callable, Iterator
from importlib.metadata import entry_points
from pathlib import Path
from typing import Generic, TypeVar

from ..errors import ConfigurationError, UnknownNameError

__all__ = ["ENTRY_POINT_GROUP", "Registry", "load_plugin"]

T = TypeVar("T")
#: The entry-point group whose modules are imported when a registry misses a name.
ENTRY_POINT_GROUP = "pendulum_cosim.plugins"


@functools.cache
def _load_entry_points() -> None:
    """Import the modules of the entry-point group (once)."""
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            ep.load()
        except Exception as e:  # noqa: BLE001 - a broken plugin must not break the project
            warnings.warn(f"plugin entry point {ep.name!r} ({ep.value}) failed to load: {e}", stacklevel=3)


def load_plugin(spec: str, base_dir: str | Path | None = None):
    """Import a plugin, whose definitions register themselves; returns the module.

    Parameters
    ----------
    spec, base_dir
        A module name (``"my_package.filters"``) or the path of a ``.py`` file; the folder a relative
        ``.py`` path refers to (default: the working directory).

    Raises
    ------
    ConfigurationError
        The module cannot be found or fails to import (the message says why).
    """
    if not isinstance(spec, str) or not spec:
        raise ConfigurationError(f"a plugin must be a module name or a .py file, got {spec!r}")
    if spec.endswith(".py"):
        path = Path(base_dir or ".", spec)        # an absolute spec stays itself
        if not path.is_file():
            raise ConfigurationError(f"plugin file {path} does not exist")
        name = f"pendulum_cosim_plugin_{path.stem}_{abs(hash(str(path.resolve()))):x}"
        if name in sys.modules:
            return sys.modules[name]
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except Exception as e:  # noqa: BLE001 - any error of the user's module becomes one named error
            del sys.modules[name]
            raise ConfigurationError(f"plugin {path} failed to import: {type(e).__name__}: {e}") from None
        return module
    try:
        return importlib.import_module(spec)
    except ImportError as e:
        raise ConfigurationError(f"plugin module {spec!r} cannot be imported: {e}") from None


class Registry(Generic[T]):
    """Named things of one kind.

    Parameters
    ----------
    kind : str
        What the registry holds, for messages (``"model"``, ``"filter"``, ...).
    """

    def __init__(self, kind: str):
        self.kind = kind
        self._items: dict[str, T] = {}
        self._aliases: dict[str, str] = {}

    def register(self, name: str, item: T | None = None, *, aliases: tuple[str, ...] = (),
                 replace: bool = False) -> T | Callable[[T], T]:
        """Register ``item`` under ``name`` (and ``aliases``); without ``item``, a decorator. Re-registering
        a name with another item is refused unless ``replace`` (the same item again, as on a reload, is not).

        Raises
        ------
        ConfigurationError
            A name that is not a string, or taken by another item.
        """
        if item is None:
            return lambda obj: self.register(name, obj, aliases=aliases, replace=replace)
        for n in (name, *aliases):
            if not isinstance(n, str) or not n:
                raise ConfigurationError(f"a {self.kind} name must be a non-empty string, got {n!r}")
            held = self._items.get(self._aliases.get(n, n))
            if held is not None and not replace and getattr(held, "__qualname__", held) != \
                    getattr(item, "__qualname__", item):
                raise ConfigurationError(f"the {self.kind} name {n!r} is taken (by {held!r})")
        self._items[name] = item
        for a in aliases:
            self._aliases[a] = name
        return item

    def get(self, name: str) -> T:
        """The item ``name`` (or an alias of it).

        Raises
        ------
        UnknownNameError
            No such name (after loading the entry-point plugins); the valid ones are listed.
        """
        if not isinstance(name, str):
            raise UnknownNameError(f"a {self.kind} name must be a string, got {name!r}; valid {self.kind}s: "
                                   f"{', '.join(self.names())}")
        if name not in self:
            _load_entry_points()
        if name not in self:
            raise UnknownNameError(f"unknown {self.kind} {name!r}; valid {self.kind}s: {', '.join(self.names())}")
        return self._items[self._aliases.get(name, name)]

    def names(self) -> list[str]:
        """The registered names, in registration order."""
        return list(self._items)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self._aliases.get(name, name) in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self._items)})"
