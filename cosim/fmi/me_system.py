"""Connected Model Exchange FMUs integrated as one system (:class:`MESystem`): one solver
for all their states, the connections evaluated inside every right-hand-side evaluation,
events handled jointly (see the third-party FMUs page of the documentation).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from itertools import accumulate, pairwise

import numpy as np

from fmu_models.errors import ConfigurationError, FMUError, TypeMismatchError, UnknownNameError
from fmu_models.infra.checks import check_unique

from ..core.component import BoundCalls, Component, Port, ports_compatible, split_port
from .exchange import no_exchange
from .fmu_component import FMUComponent, HeldInputs
from .model_exchange import ContinuousModel, FMUModel, MEIntegrator, check_solver, held_inputs, unit_nominals_instead

__all__ = ["MESystem"]

#: Most rounds of the joint event iteration (each a round of every member's own iteration).
MAX_EVENT_ROUNDS = 1000


def _slices(sizes: list[int]) -> list[slice]:
    """Consecutive slices of these sizes."""
    return [slice(a, b) for a, b in pairwise(accumulate(sizes, initial=0))]


class _Coupled(ContinuousModel):
    """The members as one :class:`~cosim.fmi.model_exchange.ContinuousModel`: states and
    indicators concatenated in member order, the connections propagated before derivatives,
    indicators and outputs."""

    def __init__(self, name: str, models: list[FMUModel], propagate):
        self.name, self.models = name, models
        self.nx, self.nz = sum(m.nx for m in models), sum(m.nz for m in models)
        self.needs_completed_step = any(m.needs_completed_step for m in models)
        self._x, self._z = _slices([m.nx for m in models]), _slices([m.nz for m in models])
        self._propagate = propagate
        self.dirty = True

    def refresh(self) -> None:
        """Propagate the continuous connections if time or states changed since."""
        if self.dirty:
            self._propagate(False)
            self.dirty = False

    def set_time(self, t):
        for m in self.models:
            m.set_time(t)
        self.dirty = True

    def get_states(self, x):
        for m, s in zip(self.models, self._x):
            m.get_states(x[s])

    def set_states(self, x):
        for m, s in zip(self.models, self._x):
            m.set_states(x[s])
        self.dirty = True

    def derivatives(self, dx):
        self.refresh()
        for m, s in zip(self.models, self._x):
            m.derivatives(dx[s])

    def indicators(self, z):
        self.refresh()
        for m, s in zip(self.models, self._z):
            m.indicators(z[s])

    def nominals(self, out):
        for m, s in zip(self.models, self._x):
            m.nominals(out[s])

    def completed_step(self):
        flags = [m.completed_step() for m in self.models if m.needs_completed_step]
        return any(enter for enter, _ in flags), any(term for _, term in flags)

    def enter_event_mode(self) -> None:
        for m in self.models:
            m.enter_event_mode()

    def settle(self, t: float) -> tuple[bool, float | None]:
        """The joint event iteration: every member's own, the connections propagated,
        until no connected value changes. A member that asks to terminate is not asked
        again; the others settle on its last values, then the system terminates."""
        stopped = set()
        for _ in range(MAX_EVENT_ROUNDS):
            self._propagate(True)
            nxt = []
            for k, m in enumerate(self.models):
                if k in stopped:
                    continue
                terminate, n = m.iterate(t)
                if terminate:
                    stopped.add(k)
                elif n is not None:
                    nxt.append(n)
            if not self._propagate(True):          # no connected value changed: settled
                self.dirty = True
                if stopped:
                    who = ", ".join(self.models[k].name for k in sorted(stopped))
                    self.stop_reason = f"member {who} requested termination in its event update"
                    return True, None
                for m in self.models:
                    m.enter_continuous_time_mode()
                return False, (min(nxt) if nxt else None)
        raise FMUError(f"{self.name}: the joint event iteration at t = {t:g} s did not settle in "
                       f"{MAX_EVENT_ROUNDS} rounds (the members' discrete values keep changing each other)")


class MESystem(BoundCalls, HeldInputs, Component, kind="me_system"):
    """Model Exchange FMUs connected to each other, integrated as one system (see the
    third-party FMUs page of the documentation).

    Parameters
    ----------
    name : str
    members : sequence of FMUComponent
        The Model Exchange FMUs, by their names (their own periods are ignored).
    connections : mapping {"member.input": "member.output"}
        The connections between members, evaluated inside every right-hand-side evaluation
        (continuous inputs) and event iteration (all inputs).
    period : float
        The communication step [s] with the master.
    solver : {"cvode", "euler", "rk4"}
    solver_step : float, optional
        Euler/RK4 step or CVODE's largest step [s] (see :class:`~cosim.fmi.FMUComponent`).
    rtol : float
        CVODE's relative tolerance (default 1e-6).

    Attributes
    ----------
    connections : dict {(member, input): (member, output)}
    integrator : MEIntegrator or None
        The integrator of the current run.
    """

    def __init__(self, name: str, members: Sequence[FMUComponent], connections: Mapping[str, str],
                 period: float, solver: str = "cvode", solver_step: float | None = None, rtol: float = 1e-6):
        self.members = list(members)
        if not self.members:
            raise ConfigurationError(f"{name}: an ME system needs at least one member")
        for m in self.members:
            if not isinstance(m, FMUComponent):
                raise TypeMismatchError(f"{name}: member {m!r} is not an FMUComponent")
            if m.interface != "me":
                raise ConfigurationError(f"{name}: member {m.name!r} is a Co-Simulation FMU; an ME system "
                                         "integrates Model Exchange FMUs (give it interface = 'me')")
            if m.isolate:
                raise ConfigurationError(f"{name}: member {m.name!r} cannot be isolated: the system calls its "
                                         "functions inside every right-hand-side evaluation")
            if m.clock_model is not None:
                raise ConfigurationError(f"{name}: member {m.name!r} has clocks; an ME system does not drive "
                                         "clocks: give it to the master as a component of its own")
        check_unique((m.name for m in self.members), f"{name}: duplicate member names:")
        self.solver, self.solver_step, self.rtol = check_solver(name, solver, solver_step, rtol)
        self.by_name = {m.name: m for m in self.members}
        self.connections = self._parse(name, connections or {})
        self.order = self._order(name)
        ins = [Port(f"{m.name}.{p.name}", p.type, p.unit, p.description) for m in self.members
               for p in m.input_ports if (m.name, p.name) not in self.connections]
        outs = [Port(f"{m.name}.{p.name}", p.type, p.unit, p.description) for m in self.members
                for p in m.output_ports]
        super().__init__(name, period, ins, outs, feedthrough=self._feedthrough_map(), port_names_are_identifiers=False)
        self.connected_inputs = list(self.input_names)
        self.integrator: MEIntegrator | None = None
        self._model: _Coupled | None = None

    @classmethod
    def from_scenario(cls, name, table, context):
        """``members``: a list of FMU tables (as ``type = "fmu"`` components, without
        ``period``; ``interface`` is ``"me"``); ``connections``: ``{"member.input" =
        "member.output"}``; the other keys as the constructor's."""
        table = dict(table)
        members = table.pop("members", None)
        if not isinstance(members, list) or not members or not all(isinstance(m, dict) for m in members):
            raise ConfigurationError(f"component {name!r}: members must be a list of FMU tables "
                                     "([[component.members]] with name and path or model)")
        built = []
        for m in members:
            m = dict(m)
            if "name" not in m:
                raise ConfigurationError(f"component {name!r}: every member needs a name")
            what = f"component {name!r}, member {m['name']!r}"
            if m.get("period") is not None:
                raise ConfigurationError(f"{what}: period is the system's")
            if m.pop("interface", "me") != "me":
                raise ConfigurationError(f"{what}: interface must be 'me'")
            built.append(FMUComponent.from_scenario(m.pop("name"), {**m, "interface": "me",
                                                                    "period": table.get("period", 1.0)}, context))
        table["members"] = built
        return context.construct(cls, name, table)

    # ------------------------------------------------------------------ description
    def _parse(self, name: str, connections: Mapping[str, str]) -> dict:
        if not isinstance(connections, Mapping):
            raise TypeMismatchError(f"{name}: connections must be a table {{\"member.input\" = \"member.output\"}}, "
                                    f"got {type(connections).__name__}")
        out = {}
        for dst, src in connections.items():
            (dm, di), (sm, so) = (split_port(dst, f"{name}: input", "member"),
                                  split_port(src, f"{name}: output", "member"))
            for m, p, kind in ((dm, di, "input"), (sm, so, "output")):
                if m not in self.by_name:
                    raise UnknownNameError(f"{name}: no member {m!r}; members: {', '.join(self.by_name)}")
                names = self.by_name[m].input_names if kind == "input" else self.by_name[m].output_names
                if p not in names:
                    raise UnknownNameError(f"{name}: member {m!r} has no {kind} {p!r}; its {kind}s: "
                                           f"{', '.join(names) or '(none)'}")
            st = self.by_name[sm].element_ports[so].type
            dt = self.by_name[dm].element_ports[di].type
            if not ports_compatible(st, dt):
                raise TypeMismatchError(f"{name}: connection {src} -> {dst}: a {st} output cannot drive a {dt} "
                                        "input")
            if (dm, di) in out:
                raise ConfigurationError(f"{name}: input {dst!r} is connected twice")
            out[(dm, di)] = (sm, so)
        return out

    def _order(self, name: str) -> list[FMUComponent]:
        """Members ordered so that each one's feed-through inputs come from those before it."""
        after = {m.name: set() for m in self.members}
        for (dm, di), (sm, _so) in self.connections.items():
            if any(di in deps for deps in self.by_name[dm].feedthrough.values()):
                after[dm].add(sm)
        order, done = [], set()
        while len(order) < len(self.members):
            ready = [m for m in self.members if m.name not in done and after[m.name] <= done]
            if not ready:
                loop = sorted(n for n in after if n not in done)
                raise ConfigurationError(f"{name}: the members {loop} feed each other's outputs through at once "
                                         "(an algebraic loop); break it with a member whose input does not reach "
                                         "its output directly")
            order += ready
            done.update(m.name for m in ready)
        return order

    def _feedthrough_map(self) -> dict[str, set[str]]:
        """The external inputs each output depends on directly (through the connections), found
        in :meth:`_order`'s order: a connected feed-through input's source output comes first."""
        deps: dict[tuple[str, str], set[str]] = {}
        for m in self.order:
            for o in m.output_names:
                found = deps[m.name, o] = set()
                for i in m.feedthrough.get(o, ()):
                    src = self.connections.get((m.name, i))
                    found |= deps[src] if src is not None else {f"{m.name}.{i}"}
        return {f"{m.name}.{o}": deps[m.name, o] for m in self.members for o in m.output_names}

    def timing(self) -> str:
        return ("Model Exchange system: outputs at t; connections between members inside every derivative "
                "evaluation; external inputs held over the step")

    def check_run(self, start_time: float, stop_time: float) -> None:
        for m in self.members:
            m.check_run(start_time, stop_time)

    # ------------------------------------------------------------------ lifecycle
    def reset(self, t0: float) -> None:
        """Instantiate and initialise every member at ``t0``, then the joint event
        iteration and the solver."""
        self.close()
        super().reset(t0)
        for m in self.members:
            m.instantiate(t0)
        self._model = self._coupled()
        self.integrator = MEIntegrator(self._model, self.solver, self.solver_step, self.rtol)
        try:
            self.integrator.start(t0)
        except FMUError:
            if not unit_nominals_instead(self._model.models, self.order):      # else: on new instances
                raise
            self.reset(t0)

    def _coupled(self) -> _Coupled:
        """The members' models and the connections propagated over a buffer of their outputs."""
        sources = sorted(set(self.connections.values()))
        slot = {s: k for k, s in enumerate(sources)}
        buf = np.zeros(max(len(sources), 1))
        ints = np.zeros(max(len(sources), 1), dtype=np.int64)
        # per member in order: its inputs from members before it (current when set), its outputs;
        # then the inputs from members after it (set once every output is current: none of them
        # reaches an output at once, or the order would differ). Getters return None: no change
        rank = {m.name: k for k, m in enumerate(self.order)}
        early, late = [], []
        for m in self.order:
            for before, phase in ((True, early), (False, late)):
                for discrete in (False, True):
                    conns = [(di, src) for (dm, di), src in self.connections.items()
                             if dm == m.name and m.element_ports[di].discrete == discrete
                             and (rank[src[0]] < rank[m.name]) == before]
                    names = [(f"{self.name}.{sm}.{so}", self.by_name[sm].element_ports[so].type)
                             for _, (sm, so) in conns]
                    ex = m.instance.exchange([m.element_ports[di] for di, _ in conns], "set", names)
                    phase.append((ex.bind(buf, np.array([slot[s] for _, s in conns], np.intp), ints, changes=True),
                                  discrete))
            mine = [s for s in sources if s[0] == m.name]
            early.append((m.instance.exchange([m.element_ports[p] for _, p in mine], "get").bind(
                buf, np.array([slot[s] for s in mine], np.intp), ints), False))
        # the calls that do nothing left out: propagate runs at every derivative evaluation
        calls = [(f, discrete) for f, discrete in early + late if f is not no_exchange]
        continuous, every = [f for f, discrete in calls if not discrete], [f for f, _ in calls]

        def propagate(discrete: bool) -> bool:
            changed = False
            for f in every if discrete else continuous:
                changed |= bool(f())
            return changed

        return _Coupled(self.name, [FMUModel(m.instance, m.unit_nominals) for m in self.order], propagate)

    def bind(self, values, inputs, outputs, integers=None):
        """Output and update closures (see :class:`~cosim.core.component.FastBinding`):
        external continuous inputs set in Continuous-Time Mode (the solver reinitialised
        where one jumped), discrete ones in Event Mode."""
        if self._model is None:
            raise FMUError(f"{self.name}: reset() must be called before bind()")
        if integers is None:
            integers = np.zeros(len(values), dtype=np.int64)
        idx, out_idx = np.arange(len(values))[inputs], np.arange(len(values))[outputs]
        sources = self._sources or [(f"{self.name}.{n}", "Float64") for n in self.connected_inputs]
        ft_names = set().union(*self.feedthrough.values()) if self.feedthrough else set()
        setters, feedthrough, getters = ([], []), ([], []), []     # (continuous, discrete) setters
        for m, mine_out in zip(self.members, _slices([len(m.output_names) for m in self.members])):
            mine = [(k, n.split(".", 1)[1]) for k, n in enumerate(self.connected_inputs)
                    if n.split(".", 1)[0] == m.name]
            for discrete in (False, True):
                sel = [(k, p) for k, p in mine if m.element_ports[p].discrete == discrete]
                ft = [(k, p) for k, p in sel if f"{m.name}.{p}" in ft_names]
                for group, chosen in ((setters, sel), (feedthrough, ft)):
                    if chosen:
                        ex = m.instance.exchange([m.element_ports[p] for _, p in chosen], "set",
                                                 [sources[k] for k, _ in chosen])
                        group[discrete].append(ex.bind(values, idx[[k for k, _ in chosen]], integers, changes=True))
            if m.output_names:
                ex = m.instance.exchange([m.element_ports[o] for o in m.output_names], "get")
                getters.append(ex.bind(values, out_idx[mine_out], integers))
        return held_inputs(self.integrator, self.period, setters, feedthrough, getters)

    def close(self) -> None:
        """End every member's instance by the FMI rules (safe twice)."""
        self._private, self._model, self.integrator = None, None, None
        for m in self.members:
            m.close()

    def release(self) -> None:
        """:meth:`close` and remove the members' unpacked files."""
        self.close()
        for m in self.members:
            m.release()
