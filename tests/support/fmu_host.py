"""A small fmpy host for FMI 2.0 and FMI 3.0 co-simulation FMUs, with the FMU's log kept.

Used by the tests that drive one FMU (or the closed loop of three) call by call: the same
calls on every family, pythonfmu and native, FMI 2.0 and 3.0.
"""

from ctypes import byref

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
from fmpy.fmi3 import FMU3Slave
from fmpy.logging import addLoggerProxy



REF = ("X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d")
CONTROLLER_INPUTS = REF + ("q1", "q2", "q3", "dq1", "dq2", "dq3")
CONTROLLER_OUTPUTS = tuple(f"{n}{i}" for n in ("F", "u", "e", "es") for i in (1, 2, 3))


class Host:
    """One instance of the FMU at ``path``; ``messages`` holds (status, category, text) of every
    log call. Instantiated with loggingOn = False: what arrives is what any host gets."""

    def __init__(self, path, unzip_dir, name="inst", logging_on=False):
        self.md = read_model_description(str(path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.messages = []
        unzip = extract(str(path), unzipdir=str(unzip_dir))
        ident = self.md.coSimulation.modelIdentifier
        if self.fmi3:
            self.fmu = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=unzip, modelIdentifier=ident,
                                 instanceName=name)
            self.fmu.instantiate(loggingOn=logging_on, logMessage=self._log3)
        else:
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            addLoggerProxy(byref(self.callbacks))
            self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=unzip, modelIdentifier=ident, instanceName=name)
            self.fmu.instantiate(callbacks=self.callbacks, loggingOn=logging_on)

    def _log2(self, env, instance, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def _log3(self, env, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    def set(self, values: dict) -> None:
        """Set Real/Float64 and Integer/Int32 variables by name."""
        for name, value in values.items():
            integer = self.types[name] in ("Integer", "Int32")
            if self.fmi3:
                (self.fmu.setInt32 if integer else self.fmu.setFloat64)([self.vr[name]], [int(value) if integer
                                                                                     else float(value)])
            else:
                (self.fmu.setInteger if integer else self.fmu.setReal)([self.vr[name]], [int(value) if integer
                                                                                     else float(value)])

    def get(self, names) -> list[float]:
        vrs = [self.vr[n] for n in names]
        return list(self.fmu.getFloat64(vrs) if self.fmi3 else self.fmu.getReal(vrs))

    def enter_initialization(self, t0=0.0) -> None:
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=t0)
        else:
            self.fmu.setupExperiment(startTime=t0)
            self.fmu.enterInitializationMode()

    def init(self, params: dict, t0=0.0) -> None:
        """Set the parameters, then Initialization Mode in and out."""
        self.set(params)
        self.enter_initialization(t0)
        self.fmu.exitInitializationMode()

    def do_step(self, t: float, h: float) -> None:
        self.fmu.doStep(t, h)

    def get_state(self):
        return self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()

    def set_state(self, state) -> None:
        (self.fmu.setFMUState if self.fmi3 else self.fmu.setFMUstate)(state)

    def warnings(self) -> list[str]:
        return [m for s, _, m in self.messages if s == 1]

    def errors(self) -> list[str]:
        return [m for s, _, m in self.messages if s >= 3]

    def close(self) -> None:
        try:
            self.fmu.terminate()
        except FMICallException:
            pass
        self.fmu.freeInstance()



def ssp_fmi2_units(ssp, folder) -> tuple[dict, list]:
    """The FMI 2.0 FMUs of the SSP file ``ssp`` unpacked into ``folder`` and instantiated in FMPy, one
    per element: ({element: (FMU2Slave, {variable: value reference}, [output names])}, [(start element,
    start connector, end element, end connector)] of the SSD's connections), elements in the SSD's order."""
    import zipfile
    from fmpy.ssp.ssd import read_ssd
    with zipfile.ZipFile(ssp) as z:
        z.extractall(folder)
    ssd = read_ssd(str(ssp))
    units = {}
    for c in ssd.system.elements:
        path = str(folder / c.source)
        md = read_model_description(path)
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(path, unzipdir=str(folder / c.name)),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName=c.name)
        refs = {v.name: v.valueReference for v in md.modelVariables}
        units[c.name] = (slave, refs, [v.name for v in md.modelVariables if v.causality == "output"])
    links = [(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections]
    return units, links
