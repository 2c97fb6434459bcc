"""One FMU instance through fmpy's FMI 2.0 API with its log messages, and the status of a call."""

from ctypes import byref

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy


class LoadedFMU:
    """One FMU instance through fmpy, with its log messages collected."""

    def __init__(self, path, tmp_path, name="inst"):
        self.md = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(self.callbacks))
        unzip = extract(str(path), unzipdir=str(tmp_path / f"{name}_unzip"))
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=unzip,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=True)

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, message.decode()))

    def set(self, **values):
        for k, v in values.items():
            if self.types[k] == "Integer":
                self.slave.setInteger([self.vr[k]], [int(v)])
            else:
                self.slave.setReal([self.vr[k]], [float(v)])

    def get(self, *names):
        return self.slave.getReal([self.vr[n] for n in names])

    def init(self, t0=0.0, **params):
        self.set(**params)
        self.slave.setupExperiment(startTime=t0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def statuses(self, **values):
        """Set values, initialize and do one step; the fmi2Status of each call, in order
        (fmpy raises FMICallException for a status above fmi2Warning)."""
        calls = {"set": lambda: self.set(**values),
                 "setupExperiment": lambda: self.slave.setupExperiment(startTime=0.0),
                 "enterInitializationMode": self.slave.enterInitializationMode,
                 "exitInitializationMode": self.slave.exitInitializationMode,
                 "doStep": lambda: self.slave.doStep(0.0, 1e-4)}
        return {name: call_status(call) for name, call in calls.items()}

    def errors(self):
        return [m for s, m in self.messages if s >= 3]

    def close(self):
        try:
            self.slave.terminate()
        except Exception:
            pass
        self.slave.freeInstance()


def call_status(call) -> int:
    """The fmi2Status of an fmpy call: 0 (or 1) if it returned, else the raised status."""
    try:
        call()
    except FMICallException as err:
        return err.status
    return 0
