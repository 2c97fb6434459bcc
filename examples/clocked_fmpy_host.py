"""Run an SSP whose FMUs may have a periodic input clock (build/native/fmi3/TAPMP_Clocked.ssp) on FMPy's
low-level FMI 3.0 API, ticking the clock at every t0 + k T_s: what FMPy's ``simulate_fmu``, fmusim and the
FMU Manipulation Toolbox do not do. It gives `tapmp run` on the same SSP (event_mode = true, the default
gauss-seidel ordering) bit for bit.

    .venv/bin/python examples/clocked_fmpy_host.py build/native/fmi3/TAPMP_Clocked.ssp --stop-time 2.5 \\
        --out results/clocked_fmpy.csv

The macro step is the clock's interval (read from the FMU after initialization). Per step from t = k h:

1. the tick at t (k > 0): ``enterEventMode``, ``setClock``, the clocked FMU's inputs (the other FMUs' outputs
   at t), ``updateDiscreteStates``, its outputs (the command sampled at t), ``enterStepMode``;
2. every FMU, the clocked one first: its inputs, ``doStep(t, h)``, its outputs.

Initialization: every FMU in Initialization Mode, every connected output read, then one FMU after the other
in the SSD's order: its inputs, ``exitInitializationMode`` (the clocked FMU is then in Event Mode, where the
tick at t0 happens), its outputs. The CSV has a row at t0 and after every step: time, then every output of
every element as ``element.variable`` (17 significant digits, so the doubles read back exactly).
"""

import argparse
import csv
import sys
import tempfile
import zipfile
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave, fmi3Float64, fmi3IntervalQualifier, fmi3ValueReference
from fmpy.ssp.ssd import read_ssd


class Element:
    """One FMU of the SSP, instantiated; ``clock`` is the value reference of its input clock (None: none)."""

    def __init__(self, name: str, fmu: Path):
        self.name = name
        self.md = read_model_description(str(fmu))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        clocks = [v for v in self.md.modelVariables if v.type == "Clock" and v.causality == "input"]
        self.clock = clocks[0].valueReference if clocks else None
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type == "Float64"]
        self.fmu = FMU3Slave(guid=self.md.guid, unzipDirectory=extract(str(fmu)),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        # an FMU with clocks runs with Event Mode (FMI 3.0.2); the others need none
        self.fmu.instantiate(eventModeUsed=self.clock is not None)
        self.values = {}  # its outputs as read last

    def read(self):
        self.values = dict(zip(self.outputs, self.fmu.getFloat64([self.vr[n] for n in self.outputs])))

    def set_inputs(self, links, elements):
        for (src, output), inp in links.get(self.name, ()):
            self.fmu.setFloat64([self.vr[inp]], [elements[src].values[output]])

    def interval(self) -> float:
        """The input clock's interval [s] (fmi3GetIntervalDecimal; FMPy 0.3.32 passes its ctypes arrays on)."""
        interval, qualifier = (fmi3Float64 * 1)(), (fmi3IntervalQualifier * 1)()
        self.fmu.getIntervalDecimal((fmi3ValueReference * 1)(self.clock), interval, qualifier)
        return interval[0]

    def tick(self, links, elements, enter=True):
        """The clock's tick at the current time: Event Mode, the clock, inputs, update, outputs, Step Mode."""
        if enter:
            self.fmu.enterEventMode()
        self.fmu.setClock([self.clock], [True])
        self.set_inputs(links, elements)
        again, terminate = self.fmu.updateDiscreteStates()[:2]
        if again or terminate:
            raise RuntimeError(f"{self.name}: updateDiscreteStates asks for another iteration or to terminate")
        self.read()
        self.fmu.enterStepMode()


def run(ssp: Path, stop_time: float, out: Path) -> int:
    """Run ``ssp`` from 0 to ``stop_time`` [s] and write the CSV ``out``; returns the number of steps."""
    ssd = read_ssd(str(ssp))
    with tempfile.TemporaryDirectory() as tmp, zipfile.ZipFile(ssp) as z:
        elements = {}
        for c in ssd.system.elements:
            elements[c.name] = Element(c.name, Path(z.extract(c.source, tmp)))
        links = {}  # {destination element: [((source element, output), input)]}
        for c in ssd.system.connections:
            links.setdefault(c.endElement, []).append(((c.startElement, c.startConnector), c.endConnector))
        clocked = [e for e in elements.values() if e.clock is not None]
        if len(clocked) != 1:
            raise SystemExit(f"error: {ssp} has {len(clocked)} FMUs with an input clock: allowed is one")
        clocked = clocked[0]
        order = [clocked] + [e for e in elements.values() if e is not clocked]  # the sampler first
        for e in elements.values():
            e.fmu.enterInitializationMode(startTime=0.0)
        for e in elements.values():
            e.read()
        for e in elements.values():
            e.set_inputs(links, elements)
            e.fmu.exitInitializationMode()
            if e is clocked:
                h = e.interval()
                e.tick(links, elements, enter=False)  # it is in Event Mode after initialization: the tick at t0
            e.read()
        columns = [f"{e.name}.{n}" for e in elements.values() for n in e.outputs]
        steps = round(stop_time / h)
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["time", *columns])

            def row(t):
                w.writerow([repr(t), *(repr(e.values[n]) for e in elements.values() for n in e.outputs)])

            row(0.0)
            for k in range(steps):
                t = k * h  # t0 + k h, the clock's own grid
                if k > 0:
                    clocked.tick(links, elements)
                for e in order:
                    e.set_inputs(links, elements)
                    if e.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)[1]:
                        raise RuntimeError(f"{e.name}: doStep at t = {t!r} s asks to terminate")
                    e.read()
                row((k + 1) * h)
        for e in elements.values():
            e.fmu.terminate()
            e.fmu.freeInstance()
    return steps


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("ssp", type=Path, help="the SSP, e.g. build/native/fmi3/TAPMP_Clocked.ssp")
    p.add_argument("--stop-time", type=float, default=2.5, help="stop time [s] (default: 2.5, the paper's run)")
    p.add_argument("--out", type=Path, default=Path("clocked_fmpy.csv"), help="the CSV to write")
    args = p.parse_args(argv)
    if not args.ssp.is_file():
        print(f"error: SSP file {args.ssp} does not exist (build it: bash build_fmus.sh --host)", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    steps = run(args.ssp, args.stop_time, args.out)
    print(f"{steps} steps, {steps + 1} ticks of the clock: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
