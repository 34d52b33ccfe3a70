"""Drive an FMU (FMI 2.0 or 3.0, CS or ME) through fmpy's low-level API, capturing log messages."""
from __future__ import annotations

from ctypes import c_double

from fmpy import extract, fmi2, fmi3, read_model_description
from fmpy.fmi1 import calloc, free


class Instance:
    """An instantiated FMU whose log messages land in ``self.messages``."""

    def __init__(self, path, kind="cs", start=None):
        self.md = read_model_description(path)
        self.version = 3 if self.md.fmiVersion.startswith("3") else 2
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.vr = {n: v.valueReference for n, v in self.vars.items()}
        iface = self.md.coSimulation if kind == "cs" else self.md.modelExchange
        args = dict(guid=self.md.guid, unzipDirectory=extract(path),
                    modelIdentifier=iface.modelIdentifier, instanceName="test")
        self.messages = []
        if self.version == 2:
            self.fmu = (fmi2.FMU2Slave if kind == "cs" else fmi2.FMU2Model)(**args)

            def logger(env, name, status, category, message):
                self.messages.append((status, message.decode()))

            cb = fmi2.fmi2CallbackFunctions()
            cb.logger = fmi2.fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(free)
            self._cb = cb
            self.fmu.instantiate(callbacks=cb)
            self.fmu.setupExperiment(startTime=0.0)
        else:
            self.fmu = (fmi3.FMU3Slave if kind == "cs" else fmi3.FMU3Model)(**args)

            def log3(env, status, category, message):
                self.messages.append((status, message.decode()))

            self.fmu.instantiate(loggingOn=True, logMessage=log3)   # FMI 3.0: no message at all without it
        for name, value in (start or {}).items():
            self.set(name, value)

    def set(self, name, value):
        v = self.vars[name]
        if v.type in ("Integer", "Enumeration", "Int32", "Int64"):
            if self.version == 2:
                self.fmu.setInteger([v.valueReference], [int(value)])
            elif v.type == "Int32":
                self.fmu.setInt32([v.valueReference], [int(value)])
            else:
                self.fmu.setInt64([v.valueReference], [int(value)])
        else:
            self.set_reals([v.valueReference], [float(value)])

    def set_reals(self, vrs, values):
        (self.fmu.setReal if self.version == 2 else self.fmu.setFloat64)(list(vrs), list(values))

    def get_reals(self, vrs):
        return list((self.fmu.getReal if self.version == 2 else self.fmu.getFloat64)(list(vrs)))

    def get(self, *names):
        return self.get_reals([self.vr[n] for n in names])

    def init(self):
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def do_step(self, t, h):
        self.fmu.doStep(t, h)

    def set_states(self, x):
        self.fmu.setContinuousStates((c_double * len(x))(*x), len(x))

    def directional(self, unknowns, knowns, seed):
        return list(self.fmu.getDirectionalDerivative(unknowns, knowns, seed))

    def get_state(self):
        return self.fmu.getFMUstate() if self.version == 2 else self.fmu.getFMUState()

    def set_state(self, s):
        (self.fmu.setFMUstate if self.version == 2 else self.fmu.setFMUState)(s)

    def free_state(self, s):
        (self.fmu.freeFMUstate if self.version == 2 else self.fmu.freeFMUState)(s)

    def serialize(self, s):
        return (self.fmu.serializeFMUstate if self.version == 2 else self.fmu.serializeFMUState)(s)

    def deserialize(self, blob):
        return (self.fmu.deSerializeFMUstate if self.version == 2 else self.fmu.deserializeFMUState)(blob)

    def free(self):
        from fmpy.fmi1 import FMICallException

        try:
            self.fmu.terminate()
        except FMICallException:    # an instance in the error state cannot terminate; free it anyway
            self.messages.append((3, "terminate refused"))
        self.fmu.freeInstance()
