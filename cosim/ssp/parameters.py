"""Parameter bindings of an SSP 1.0 system: parameter sets (inline or ``.ssv`` files), parameter
mappings (inline or ``.ssm`` files) with their transformations, the ``prefix``, the values' units."""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from fmu_models.errors import ConfigurationError, FMUError
from fmu_models.infra.checks import finite

from .schema import NS, Transformation, Unit, parse_bool, parse_int, parse_xml, q, read_units

__all__ = ["Value", "binding_values"]

#: The value elements of a parameter set (SSP 1.0 and the typed ones of later versions), by kind.
_KINDS = {"Real": "real", "Float64": "real", "Float32": "real", "Integer": "integer", "Boolean": "boolean",
          "String": "string", "Enumeration": "enumeration",
          **{t: "integer" for t in ("Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")}}
PARAMETER_SET = "application/x-ssp-parameter-set"
PARAMETER_MAPPING = "application/x-ssp-parameter-mapping"


@dataclass(frozen=True)
class Value:
    """A parameter value from a binding.

    Attributes
    ----------
    name, value, kind
        Its hierarchical name (the prefix and mapping applied), the value and its kind: "real",
        "integer", "boolean", "string" or "enumeration".
    unit, convert : Unit or None, bool
        The unit the value is given in (reals), if the parameter set names one; whether it is converted
        to the unit of the variable it sets (not where a mapping entry says ``suppressUnitConversion``).
    where : str
        Where it was read (for messages).
    """

    name: str
    value: object
    kind: str
    unit: Unit | None
    convert: bool
    where: str


def _parse_value(p, units: dict[str, Unit], where: str) -> Value:
    name = p.get("name")
    for child in p.findall("ssv:*", NS):
        kind = _KINDS.get(child.tag.rpartition("}")[2])
        if kind is None:
            continue
        text, what = child.get("value"), f"{where}: parameter {name!r}"
        unit = child.get("unit") if kind == "real" else None
        if unit is not None and unit not in units:
            raise ConfigurationError(f"{what} names the unit {unit!r}, which its parameter set does not define")
        parse = {"real": finite, "integer": parse_int, "boolean": parse_bool}.get(kind)
        return Value(name, text if parse is None else parse(text, what), kind, units.get(unit), True, where)
    raise ConfigurationError(f"{where}: parameter {name!r} has no value of a known type "
                             f"({', '.join(sorted(set(_KINDS)))})")


def _resolve(base: Path, root: Path, source: str, where: str) -> Path:
    """``source`` (a relative URI) below ``base``, refused if it leaves the SSP ``root``."""
    if ":" in source.split("/", 1)[0]:
        raise ConfigurationError(f"{where}: source {source!r} is not a relative path inside the SSP (absolute "
                                 "URIs are not read)")
    path = (base / source).resolve()
    if path != root.resolve() and root.resolve() not in path.parents:
        raise FMUError(f"{where}: source {source!r} points outside the SSP")
    if not path.is_file():
        raise FMUError(f"{where}: source {source!r} is not in the SSP")
    return path


def _document(holder, tag: str, inline: str, kind: str, base: Path, root: Path, where: str):
    """The ``tag`` document of ``holder`` (a binding or its ``ParameterMapping``): its ``source``
    file, else the element at ``inline`` below it (or None); and where it was read."""
    mime = holder.get("type", kind)
    if mime != kind:
        raise ConfigurationError(f"{where}: type {mime!r} is not read (only {kind})")
    if holder.get("sourceBase", "SSD") != "SSD":
        raise ConfigurationError(f"{where}: sourceBase {holder.get('sourceBase')!r} (a file inside a component) "
                                 "is not read; give the file beside the SSD")
    source = holder.get("source")
    if not source:
        return holder.find(inline, NS), where
    path = _resolve(base, root, source, where)
    doc, where = parse_xml(path, "a parameter file"), f"{where} ({source})"
    if doc.tag != q(tag):
        raise FMUError(f"{where}: not an SSP {tag.split(':')[1]} file (its root is {doc.tag.rpartition('}')[2]})")
    return doc, where


def _mapping(binding, base: Path, root: Path, where: str) -> dict[str, tuple[str, Transformation | None, bool]]:
    """A binding's parameter mapping: source name -> (target name, transformation, convert units)."""
    holder = binding.find("ssd:ParameterMapping", NS)
    if holder is None:
        return {}
    doc, where = _document(holder, "ssm:ParameterMapping", "ssm:ParameterMapping", PARAMETER_MAPPING, base, root,
                           f"{where} ParameterMapping")
    out = {}
    for e in ([] if doc is None else doc.findall("ssm:MappingEntry", NS)):
        src, dst = e.get("source"), e.get("target")
        if not src or not dst:
            raise ConfigurationError(f"{where}: a MappingEntry without source or target")
        out[src] = (dst, Transformation.read(e, f"{where}: entry {src!r}"),
                    e.get("suppressUnitConversion", "false") not in ("true", "1"))
    return out


def binding_values(binding, base: Path, root: Path, where: str) -> list[Value]:
    """The values of one ``ssd:ParameterBinding``, in their order, with the binding's prefix
    prepended to their names and its mapping applied.

    Parameters
    ----------
    binding, where : Element, str
        The ``ssd:ParameterBinding``; its place, for messages.
    base, root : Path
        The SSD's folder (relative sources are resolved against it) and the SSP's (no source may leave it).
    """
    doc, where = _document(binding, "ssv:ParameterSet", "ssd:ParameterValues/ssv:ParameterSet", PARAMETER_SET,
                           base, root, where)
    if doc is None:
        return []
    units = read_units(doc.find("ssv:Units", NS), where)
    prefix = binding.get("prefix", "")
    mapping = _mapping(binding, base, root, where)
    out = []
    for p in doc.findall("ssv:Parameters/ssv:Parameter", NS):
        v = _parse_value(p, units, where)
        name = prefix + v.name
        target, transform, convert = mapping.get(name, (name, None, v.convert))
        value = v.value if transform is None else transform.apply(v.value, f"{where}: parameter {name!r}")
        out.append(replace(v, name=target, value=value, convert=convert))
    return out
