"""Static analysis of a co-simulation before it runs: the base step (:func:`~cosim.core.schedule.base_step`)
and the evaluation order of the outputs at an instant (:func:`~cosim.core.schedule.evaluation_order`), as
the co-simulation page of the documentation describes them (order, timing and latency).
"""
from __future__ import annotations

import functools
import heapq
import itertools
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components

from fmu_models.errors import ConfigurationError, ResourceError

from .clocking import fraction_gcd
from .component import Component

__all__ = ["MAX_HYPERPERIOD", "MAX_RATIO", "Group", "Unit", "base_step", "evaluation_order"]

#: Largest period / base step ratio accepted (a base step a million times shorter than a
#: period means periods that are not commensurate in practice).
MAX_RATIO = 1_000_000
#: Largest hyperperiod, in base steps, of the precomputed schedule.
MAX_HYPERPERIOD = 100_000


@functools.lru_cache(maxsize=1024)
def _fraction(x: float) -> Fraction:
    return Fraction(x).limit_denominator(10**9)


def base_step(periods: Mapping[str, float], step_size: float | None = None
              ) -> tuple[Fraction, dict[str, int], int]:
    """``(base, ratios, hyper)``: the base step [s] as a Fraction, each period in base
    steps, and the hyperperiod in base steps.

    Raises
    ------
    ConfigurationError
        A period is not a multiple of a given ``step_size``, or the periods are not
        commensurate within :data:`MAX_RATIO` / :data:`MAX_HYPERPERIOD` (the message
        names them).
    """
    if not periods:
        raise ConfigurationError("no components")
    fr = {n: _fraction(p) for n, p in periods.items()}
    if step_size is None:
        base = fraction_gcd(*fr.values())
    else:
        base = _fraction(step_size)
        if base <= 0:
            raise ConfigurationError(f"step_size must be > 0, got {step_size}")
    ratios = {}
    for name, p in fr.items():
        r = p / base
        if r.denominator != 1:
            raise ConfigurationError(f"component {name!r}: period {float(p)} s is not an integer multiple "
                                     f"of the base step {float(base)} s")
        ratios[name] = r.numerator
    listing = ", ".join(f"{n} {float(p):g} s" for n, p in fr.items())
    worst = max(ratios, key=ratios.get)
    if ratios[worst] > MAX_RATIO:
        raise ConfigurationError(
            f"the periods ({listing}) are not commensurate: their common base step would be "
            f"{float(base):.3g} s, {ratios[worst]} times shorter than {worst!r}'s period (limit "
            f"{MAX_RATIO}). Use periods that are multiples of a common step (e.g. round them), "
            "or set step_size and periods that divide it")
    for hyper in itertools.accumulate(ratios.values(), math.lcm):
        if hyper > MAX_HYPERPERIOD:
            raise ResourceError(
                f"the periods ({listing}) repeat their pattern only every {hyper}+ base steps of "
                f"{float(base):.3g} s (limit {MAX_HYPERPERIOD}); choose periods with a small least "
                "common multiple")
    return base, ratios, hyper


@dataclass(frozen=True, eq=False)       # identity: each unit is made once per analysis
class Unit:
    """One evaluation of a component's ``output`` at an instant.

    ``part`` is ``"all"``, or, for a component split to break a component-level cycle,
    ``"free"`` (its outputs that depend on no input) and later ``"dependent"``; ``ports``
    are the outputs it computes, ``needs`` the inputs they depend on directly.
    """

    comp: Component
    part: str
    ports: frozenset
    needs: frozenset

    def __str__(self) -> str:
        return self.comp.name if self.part == "all" else f"{self.comp.name} ({self.part} outputs)"


@dataclass(frozen=True)
class Group:
    """``units`` evaluated together: one unit, or an algebraic loop solved by iteration
    (``loop``)."""

    units: tuple
    loop: bool = False


def _units(comp: Component, connected: set[str], split: bool) -> list[Unit]:
    ft = {o: frozenset(comp.feedthrough.get(o, ())) & connected for o in comp.output_names}
    free = frozenset(o for o, d in ft.items() if not d)
    dep = frozenset(comp.output_names) - free
    needs = frozenset().union(*ft.values())
    if split and free and dep:
        return [Unit(comp, "free", free, frozenset()), Unit(comp, "dependent", dep, needs)]
    return [Unit(comp, "all", frozenset(comp.output_names), needs)]


def _sccs(units: list, edges: dict) -> list[list]:
    """Strongly connected components of the graph ``edges`` among ``units``, each in ``units`` order."""
    at = {u: i for i, u in enumerate(units)}
    arcs = np.array([(at[u], at[v]) for u in units for v in edges.get(u, ()) if v in at], dtype=np.intp).reshape(-1, 2)
    graph = coo_array((np.ones(len(arcs)), (arcs[:, 0], arcs[:, 1])), shape=(len(units), len(units)))
    sccs: dict = {}
    for u, label in zip(units, connected_components(graph, connection="strong")[1]):
        sccs.setdefault(label, []).append(u)
    return list(sccs.values())


def _graph(units: list[Unit], conn: Mapping) -> tuple[dict, dict]:
    """Edges ``src unit -> dst unit`` (a dst feedthrough input reads a src output), with the
    connection ``(src port ref, dst port ref)`` behind each edge."""
    publisher = {(u.comp.name, p): u for u in units for p in u.ports}
    edges, why = {u: [] for u in units}, {}
    for u in units:
        for q in sorted(u.needs):
            src = conn[(u.comp.name, q)]
            s = publisher[src]
            if (s, u) not in why:
                edges[s].append(u)
            why[(s, u)] = (f"{src[0]}.{src[1]}", f"{u.comp.name}.{q}")
    return edges, why


def _cycle(scc: list, edges: dict, why: dict) -> str:
    """A readable cycle through the units of one strongly connected component."""
    members, path, seen = set(scc), [scc[-1]], {scc[-1]: 0}
    while (nxt := next(w for w in edges[path[-1]] if w in members)) not in seen:
        seen[nxt] = len(path)
        path.append(nxt)
    cycle = path[seen[nxt]:] + [nxt]
    return ", ".join(f"{why[(a, b)][0]} -> {why[(a, b)][1]}" for a, b in itertools.pairwise(cycle))


def evaluation_order(components: Sequence[Component], conn: Mapping, loops: str = "refuse"
                     ) -> list[Group]:
    """The groups of units in evaluation order at an instant.

    Parameters
    ----------
    components : sequence of Component
        In the user's order (used only to break ties, so results do not depend on it).
    conn : mapping
        ``(dst component, input) -> (src component, output)`` for every connection.
    loops : {"refuse", "iterate"}
        What an algebraic loop does: raise :class:`ConfigurationError` naming its ports,
        or become a :class:`Group` with ``loop=True`` (all its components must be
        ``reentrant``).
    """
    connected: dict[str, set] = {c.name: set() for c in components}
    for (d, q) in conn:
        if d in connected:
            connected[d].add(q)
    split: set[str] = set()
    while True:                 # split the reentrant components of a cycle, while that breaks one
        units = [u for c in components for u in _units(c, connected[c.name], c.name in split)]
        edges, why = _graph(units, conn)
        cyclic = [s for s in _sccs(units, edges) if len(s) > 1 or s[0] in edges[s[0]]]
        more = {u.comp.name for s in cyclic for u in s
                if u.comp.reentrant and u.comp.name not in split
                and len(_units(u.comp, connected[u.comp.name], True)) == 2}
        if not more:
            break
        split |= more
    for s in cyclic:
        _check_loop(s, edges, why, loops)
    node_of = {u: u for u in units} | {u: ("loop", i) for i, s in enumerate(cyclic) for u in s}
    rank = {c.name: i for i, c in enumerate(components)}
    return _topological(units, edges, node_of, lambda u: (rank[u.comp.name], u.part != "free"))


def _check_loop(scc: list, edges: dict, why: dict, loops: str) -> None:
    """Refuse the algebraic loop ``scc`` unless ``loops="iterate"`` and every one of its
    components can evaluate its outputs twice at an instant."""
    if loops != "iterate":
        raise ConfigurationError(
            f"algebraic loop: {_cycle(scc, edges, why)}. Each of these components' outputs depends "
            "directly on its input at the same instant, so no order can evaluate them. Break the "
            "loop (a component without feedthrough, e.g. an FMU with feedthrough='none', or a "
            "delay), or solve it with loops='iterate'")
    stiff = sorted({u.comp.name for u in scc if not u.comp.reentrant})
    if stiff:
        raise ConfigurationError(
            f"algebraic loop {_cycle(scc, edges, why)} cannot be iterated: {', '.join(stiff)} "
            "cannot evaluate its outputs twice at one instant (reentrant = False)")


def _topological(units: list[Unit], edges: dict, node_of: dict, key) -> list[Group]:
    """The groups in a topological order of the condensation (``node_of``: each unit's node,
    itself or its loop), by Kahn's algorithm; among the nodes ready, the one whose first
    member (by ``key``) comes first."""
    members: dict = {}
    for u in units:
        members.setdefault(node_of[u], []).append(u)
    succ: dict = {n: set() for n in members}
    for u, vs in edges.items():
        succ[node_of[u]].update(node_of[v] for v in vs if node_of[v] != node_of[u])
    indeg = Counter(b for bs in succ.values() for b in bs)
    rank = {}
    for i, (n, ms) in enumerate(members.items()):
        ms.sort(key=key)
        rank[n] = (key(ms[0]), i)                       # i: a total order among equal keys
    ready = [(rank[n], n) for n in members if indeg[n] == 0]
    heapq.heapify(ready)
    order: list[Group] = []
    while ready:
        n = heapq.heappop(ready)[1]
        order.append(Group(tuple(members[n]), loop=isinstance(n, tuple)))
        for m in succ[n]:
            indeg[m] -= 1
            if indeg[m] == 0:
                heapq.heappush(ready, (rank[m], m))
    return order
