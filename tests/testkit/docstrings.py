"""The public names of the three packages, walked from their ``__init__`` (a new module is
found without being listed)."""
import importlib
import inspect
import pkgutil

PACKAGES = ("fmu_models", "estimators", "cosim")


def modules():
    for pkg_name in PACKAGES:
        pkg = importlib.import_module(pkg_name)
        yield pkg
        for info in pkgutil.walk_packages(pkg.__path__, prefix=f"{pkg_name}."):
            if info.name.endswith("__main__"):
                continue
            yield importlib.import_module(info.name)


def public_objects(private_modules: bool = True):
    """``(qualified name, object)`` of every public class and function (also those of private
    modules such as ``estimators._fold`` unless ``private_modules`` is False)."""
    seen = set()
    for mod in modules():
        if not private_modules and any(part.startswith("_") for part in mod.__name__.split(".")):
            continue
        names = getattr(mod, "__all__", None)
        if names is None:
            names = [n for n in dir(mod) if not n.startswith("_")]
        for name in names:
            obj = getattr(mod, name)
            if not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            if obj.__module__.split(".")[0] not in PACKAGES or obj.__name__.startswith("_"):
                continue
            key = (obj.__module__, obj.__qualname__)
            if key not in seen:
                seen.add(key)
                yield f"{obj.__module__}.{obj.__qualname__}", obj
