"""A fixed-step SSP master as other FMI tools run one (test oracle for issue 19).

Written for the tests from the FMI and SSP standards alone, with fmpy's SSD reader and its
FMU2Slave (third-party parts), not the project's master: one communication step ``h`` for
every FMU, time advanced as OMSimulator does (``t += h``, a last short step to reach the
stop time), FMUs evaluated at each communication point in an order that puts every
direct-feedthrough connection's source first (from the FMUs' declared output
dependencies), inputs set from the values of the same point (Gauss-Seidel), then every FMU
stepped over ``[t, t + h]`` with every input set from the values of that point.
"""
from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.ssp.ssd import read_ssd


def _feedthrough_inputs(md) -> set[str]:
    """Names of the inputs some output depends on directly."""
    by_index = {i + 1: v for i, v in enumerate(md.modelVariables)}
    deps = set()
    for out in md.outputs:
        for d in out.dependencies or []:
            v = d if hasattr(d, "name") else by_index[int(d)]
            if v.causality == "input":
                deps.add(v.name)
    return deps


def run_fixed_step(ssp: Path, h: float, stop: float | None = None) -> dict[str, np.ndarray]:
    """Run the SSP archive ``ssp`` with communication step ``h`` [s] to ``stop`` (default its
    DefaultExperiment stop time); returns ``{"time": ..., "<component>.<output>": ...}`` of
    the values at every communication point."""
    ssd = read_ssd(str(ssp))
    stop = float(stop if stop is not None else ssd.defaultExperiment.stopTime)
    work = Path(tempfile.mkdtemp(prefix="fixed-step-"))
    slaves, mds, vrs = {}, {}, {}
    try:
        with zipfile.ZipFile(ssp) as z:
            z.extractall(work)
        params = {}
        for binding in ssd.system.parameterBindings:
            for pset in binding.parameterValues:
                for p in pset.parameters:
                    comp, _, var = p.name.partition(".")
                    params.setdefault(comp, {})[var] = (p.type, p.value)
        for e in ssd.system.elements:
            md = read_model_description(str(work / e.source))
            unzipped = extract(str(work / e.source), unzipdir=str(work / f"unz-{e.name}"))
            s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=e.name)
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            vrs[e.name] = {v.name: v for v in md.modelVariables}
            for var, (kind, value) in params.get(e.name, {}).items():
                v = vrs[e.name][var]
                if kind == "Real":
                    s.setReal([v.valueReference], [float(value)])
                elif kind == "Integer":
                    s.setInteger([v.valueReference], [int(value)])
                else:
                    s.setBoolean([v.valueReference], [value in (True, "true", "1")])
            s.exitInitializationMode()
            slaves[e.name], mds[e.name] = s, md
        conns = [(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections]
        # order: a component after the sources of its direct-feedthrough inputs (Kahn)
        ft = {n: _feedthrough_inputs(md) for n, md in mds.items()}
        after = {n: {se for se, _, de, dc in conns if de == n and dc in ft[n]} for n in slaves}
        order = []
        while len(order) < len(slaves):
            ready = [n for n in slaves if n not in order and after[n] <= set(order)]
            assert ready, f"algebraic loop among {set(slaves) - set(order)}"
            order += ready
        outputs = {n: [v for v in mds[n].modelVariables if v.causality == "output"] for n in slaves}
        rows = {"time": []} | {f"{n}.{v.name}": [] for n in slaves for v in outputs[n]}
        values: dict[tuple[str, str], float] = {}
        t = 0.0
        while True:
            for n in order:
                for se, sc, de, dc in conns:
                    if de == n and dc in ft[n]:      # sources already evaluated at this point
                        slaves[n].setReal([vrs[n][dc].valueReference], [values[se, sc]])
                got = slaves[n].getReal([v.valueReference for v in outputs[n]])
                for v, x in zip(outputs[n], got):
                    values[n, v.name] = x
            rows["time"].append(t)
            for n in slaves:
                for v in outputs[n]:
                    rows[f"{n}.{v.name}"].append(values[n, v.name])
            if t >= stop:
                break
            step = min(h, stop - t)
            for se, sc, de, dc in conns:                 # every input as at this point, held over the step
                slaves[de].setReal([vrs[de][dc].valueReference], [values[se, sc]])
            for n in order:
                slaves[n].doStep(currentCommunicationPoint=t, communicationStepSize=step)
            t += step
        return {k: np.array(v) for k, v in rows.items()}
    finally:
        for s in slaves.values():
            s.terminate()
            s.freeInstance()
        shutil.rmtree(work, ignore_errors=True)
