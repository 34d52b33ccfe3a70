"""The XML of SSP 1.0 files as this project reads them: namespaces, size-limited parsing, the unit
definitions and the linear and mapping transformations of ``SystemStructureCommon``."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

from fmu_models.errors import ConfigurationError, FMUError
from fmu_models.infra.checks import finite

__all__ = ["MAX_XML_BYTES", "NS", "Transformation", "Unit", "parse_bool", "parse_int", "parse_xml", "q", "read_units",
           "unit_factor"]

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping"}
#: The largest SSD, SSV or SSM file read (checked before parsing; an SSD of a few hundred
#: components is well under 1 MiB).
MAX_XML_BYTES = 16 * 2**20
#: The SI base units of SSP's ``BaseUnit`` (exponents), in its order.
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def q(tag: str) -> str:
    """The prefixed ``tag`` (``"ssd:System"``) as ElementTree names it (``"{namespace}System"``)."""
    prefix, local = tag.split(":")
    return f"{{{NS[prefix]}}}{local}"


def parse_xml(path: Path, what: str) -> ET.Element:
    """The root of the XML file ``path`` (``what`` it is, for messages): an oversized file is
    refused before it is read, the rest is read in 1 MiB pieces (Ctrl-C is seen between them)."""
    try:
        size = path.stat().st_size
    except OSError as e:
        raise FMUError(f"{what} {path.name}: cannot be read ({e.strerror or e})") from None
    if size > MAX_XML_BYTES:
        raise FMUError(f"{path.name}: {size / 2**20:.0f} MiB, more than {MAX_XML_BYTES // 2**20} MiB for {what}; "
                       "refused before parsing")
    parser = ET.XMLParser()
    try:
        with open(path, "rb") as f:
            while chunk := f.read(1 << 20):
                parser.feed(chunk)
        return parser.close()
    except ET.ParseError as e:
        raise FMUError(f"{path.name}: not valid XML: {e}") from None


@dataclass(frozen=True)
class Unit:
    """A unit as SSP and FMI define it: ``value_SI = factor * value + offset`` in the SI base
    units with the exponents ``exponents`` (kg, m, s, A, K, mol, cd, rad).

    Attributes
    ----------
    name, exponents, factor, offset : str, tuple of int, float
        The exponents are empty for a unit known by name only (no definition).
    """

    name: str
    exponents: tuple[int, ...]
    factor: float = 1.0
    offset: float = 0.0


def _base_unit(name: str, base, where: str) -> Unit:
    if base is None:
        return Unit(name, (0,) * len(BASE_UNITS))
    try:
        exps = tuple(int(base.get(k, "0")) for k in BASE_UNITS)
    except ValueError:
        raise ConfigurationError(f"{where}: unit {name!r} has an exponent that is not an integer") from None
    factor = finite(base.get("factor", "1"), f"{where}: the factor of unit {name!r}")
    if factor == 0:
        raise ConfigurationError(f"{where}: unit {name!r} has the factor 0")
    return Unit(name, exps, factor, finite(base.get("offset", "0"), f"{where}: the offset of unit {name!r}"))


def read_units(units, where: str) -> dict[str, Unit]:
    """The ``ssc:Unit`` definitions below ``units`` (an ``Units`` element or None) by name;
    ``where`` names the file in messages."""
    if units is None:
        return {}
    return {u.get("name"): _base_unit(u.get("name"), u.find("ssc:BaseUnit", NS), where)
            for u in units.findall("ssc:Unit", NS)}


def unit_factor(src: Unit, dst: Unit, where: str) -> tuple[float, float]:
    """``(a, b)`` with ``value_dst = a * value_src + b`` (a ConfigurationError naming ``where`` if
    the units measure different quantities)."""
    if src.exponents != dst.exponents:
        def text(u: Unit) -> str:
            return " ".join(f"{b}^{e}" for b, e in zip(BASE_UNITS, u.exponents) if e) or "1"
        raise ConfigurationError(f"{where}: unit {src.name!r} ({text(src)}) cannot be converted to "
                                 f"{dst.name!r} ({text(dst)})")
    return src.factor / dst.factor, (src.offset - dst.offset) / dst.factor


def parse_bool(text: str | None, what: str) -> bool:
    """The xs:boolean ``text`` (``true``, ``false``, ``1``, ``0``) of ``what``, else ConfigurationError."""
    if text not in ("true", "false", "1", "0"):
        raise ConfigurationError(f"{what} has the value {text!r}, not true or false")
    return text in ("true", "1")


def parse_int(text: str | None, what: str) -> int:
    """The integer ``text`` of ``what``, else ConfigurationError."""
    try:
        return int(text)
    except (TypeError, ValueError):
        raise ConfigurationError(f"{what} has the value {text!r}, not an integer") from None


@dataclass(frozen=True)
class Transformation:
    """A transformation of a connection's or a mapped parameter's value.

    Attributes
    ----------
    kind, factor, offset, table
        ``"linear"`` (``target = factor * source + offset``), or ``"boolean"``, ``"integer"``,
        ``"enumeration"`` with the mapping entries ``table``, (source, target) pairs (enumerations: item names).
    """

    kind: str
    factor: float = 1.0
    offset: float = 0.0
    table: tuple = ()

    @classmethod
    def read(cls, parent, where: str) -> Transformation | None:
        """The transformation element below ``parent`` (a connection or mapping entry), if any."""
        e = parent.find("ssc:LinearTransformation", NS)
        if e is not None:
            return cls("linear", finite(e.get("factor", "1"), f"{where}: LinearTransformation factor"),
                       finite(e.get("offset", "0"), f"{where}: LinearTransformation offset"))
        for kind, conv in (("boolean", parse_bool), ("integer", parse_int), ("enumeration", lambda text, _: text)):
            tag = f"{kind.capitalize()}MappingTransformation"
            e = parent.find(f"ssc:{tag}", NS)
            if e is None:
                continue
            entries = e.findall("ssc:MapEntry", NS)
            if not entries:
                raise ConfigurationError(f"{where}: {tag} without a MapEntry")
            return cls(kind, table=tuple((conv(m.get("source"), f"{where}: {tag} source"),
                                          conv(m.get("target"), f"{where}: {tag} target")) for m in entries))
        return None

    def apply(self, value, where: str):
        """The transformed ``value`` (a mapping table's missing source value is an error naming
        ``where``)."""
        if self.kind == "linear":
            return self.factor * value + self.offset
        for s, t in self.table:
            if s == value:
                return t
        raise ConfigurationError(f"{where}: the {self.kind} mapping has no entry for the value {value!r}")

