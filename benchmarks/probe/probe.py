"""The probe FMU (benchmarks/probe/probe_fmu.c): built, placed into a copy of an SSP, and its record read
back as the lateness of each doStep against a real-time schedule."""

import re
import tempfile
import uuid
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "probe_fmu.c"
MODEL = "TAPMP_Probe"
ELEMENT = "probe"

MODEL_DESCRIPTION = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{model}" guid="{guid}" description="notes the wall time \
(CLOCK_MONOTONIC) of each doStep into the file `file`: t, h and the wall time per line" generationTool="tapmp \
benchmarks/probe" variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{model}" canHandleVariableCommunicationStepSize="true" \
canNotUseMemoryManagementFunctions="true"/>
  <DefaultExperiment startTime="0" stopTime="1" stepSize="0.0001"/>
  <ModelVariables>
    <ScalarVariable name="file" valueReference="0" description="the file written at fmi2Terminate: one line \
't h wall_ns' per doStep" causality="parameter" variability="fixed" initial="exact">
      <String start="{file}"/>
    </ScalarVariable>
    <ScalarVariable name="steps" valueReference="1" description="doSteps so far" causality="output" \
variability="discrete" initial="exact">
      <Real start="0"/>
    </ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs>
      <Unknown index="2" dependencies=""/>
    </Outputs>
  </ModelStructure>
</fmiModelDescription>
"""

COMPONENT = """      <ssd:Component name="{element}" type="application/x-fmu-sharedlibrary" source="resources/{model}.fmu">
        <ssd:Connectors>
          <ssd:Connector name="steps" kind="output">
            <ssc:Real />
          </ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>
"""


def build_probe(fmu: Path, record: Path) -> Path:
    """The probe FMU (FMI 2.0 CS, this machine's binary) at ``fmu``, whose parameter `file` starts as the
    absolute path ``record`` (compiled in as the start value, so every master that never sets it still
    writes there); returns ``fmu``."""
    from ctoolchain import CFLAGS, compile_c
    from orchestrator.builder.build_native import fmi_headers_dir
    record = str(Path(record).resolve())
    if re.search(r'["\\&<>\n]', record):
        raise ValueError(f"record = {record!r} is invalid: allowed is a path without quotes, backslashes, &, < or >")
    with tempfile.TemporaryDirectory(prefix="tapmp_probe_") as tmp:
        so = compile_c([SOURCE], Path(tmp) / f"{MODEL}.so", flags=CFLAGS, includes=[fmi_headers_dir()],
                       extra=[f'-DPROBE_FILE="{record}"'])
        part = fmu.with_name(fmu.name + ".part")
        with zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml",
                       MODEL_DESCRIPTION.format(model=MODEL, guid="{" + str(uuid.uuid4()) + "}", file=record))
            z.write(so, f"binaries/linux64/{MODEL}.so")
            z.write(SOURCE, "sources/probe_fmu.c")
        part.replace(fmu)
    return fmu


def with_probe(ssp: Path, probe_fmu: Path, out: Path) -> Path:
    """A copy of ``ssp`` at ``out`` with the probe FMU as one more component, `probe`, connected to nothing;
    returns ``out``."""
    part = out.with_name(out.name + ".part")
    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "SystemStructure.ssd":
                text = data.decode()
                if text.count("</ssd:Elements>") != 1:
                    raise ValueError(f"{ssp}: SystemStructure.ssd has not exactly one <ssd:Elements> (it has "
                                     f"{text.count('</ssd:Elements>')})")
                data = text.replace("</ssd:Elements>", COMPONENT.format(element=ELEMENT, model=MODEL)
                                    + "    </ssd:Elements>").encode()
            dst.writestr(item, data)
        dst.write(probe_fmu, f"resources/{MODEL}.fmu")
    part.replace(out)
    return out


def read_record(path: Path) -> np.ndarray:
    """The probe's record: rows (t [s], h [s], wall [ns]), one per doStep."""
    text = Path(path).read_text()
    if not text.strip():
        raise ValueError(f"{path}: the probe recorded no doStep")
    rows = np.loadtxt(text.splitlines(), dtype=np.float64, ndmin=2)
    if rows.shape[1] != 3:
        raise ValueError(f"{path}: {rows.shape[1]} columns, the probe writes 3 (t h wall_ns)")
    return rows


def lateness(rows: np.ndarray, factor: float) -> dict:
    """How a master kept the schedule t0_wall + (t - t0) / factor, t0_wall = its first doStep: the lateness of
    each doStep [s] (p50, p99, p99.9, max), the achieved real-time factor (simulated time / wall time between
    the first and the last doStep) and the overruns (doSteps called more than one macro step h / factor late)."""
    t, h, wall = rows[:, 0], rows[:, 1], rows[:, 2] * 1e-9
    late = (wall - wall[0]) - (t - t[0]) / factor
    span = wall[-1] - wall[0]
    return {"steps": len(rows),
            "lateness_s": {"p50": float(np.percentile(late, 50)), "p99": float(np.percentile(late, 99)),
                           "p999": float(np.percentile(late, 99.9)), "max": float(late.max())},
            "achieved_factor": float((t[-1] - t[0]) / span) if span > 0 else float("inf"),
            "overruns": int(np.count_nonzero(late > h / factor))}

