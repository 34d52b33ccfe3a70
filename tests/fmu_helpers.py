"""Helpers to drive an FMU through fmpy's low-level API in tests, with captured log messages."""
from __future__ import annotations

from ctypes import byref

from fmpy import extract, read_model_description
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackAllocateMemoryTYPE,
                       fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.fmi1 import calloc, free


class Instance:
    """An instantiated FMU (CS or ME) whose log messages land in ``self.messages``."""

    def __init__(self, path, kind="cs", start=None):
        self.md = read_model_description(path)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.unzip = extract(path)
        cls = FMU2Slave if kind == "cs" else FMU2Model
        ident = (self.md.coSimulation if kind == "cs" else self.md.modelExchange).modelIdentifier
        self.fmu = cls(guid=self.md.guid, unzipDirectory=self.unzip, modelIdentifier=ident,
                       instanceName="test")
        self.messages = []

        def logger(env, name, status, category, message):
            self.messages.append((status, message.decode()))

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(logger)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        self._cb = cb
        self.fmu.instantiate(callbacks=cb)
        self.fmu.setupExperiment(startTime=0.0)
        for name, value in (start or {}).items():
            self.set(name, value)

    def set(self, name, value):
        v = next(v for v in self.md.modelVariables if v.name == name)
        if v.type in ("Integer", "Enumeration"):
            self.fmu.setInteger([v.valueReference], [int(value)])
        else:
            self.fmu.setReal([v.valueReference], [float(value)])

    def get(self, *names):
        return self.fmu.getReal([self.vr[n] for n in names])

    def init(self):
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def free(self):
        try:
            self.fmu.terminate()
        except Exception:
            pass
        self.fmu.freeInstance()
