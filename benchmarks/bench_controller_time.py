"""The controller's execution time per sample against its 100 us cycle. Run from the repository root
after `tapmp build` (or with --build):

    .venv/bin/python benchmarks/bench_controller_time.py [--samples 1000000] [--json PATH]

A small C host (benchmarks/controller_time.c, compiled by the project's toolchain with the C model
from the controller FMU's sources/) drives one native controller FMU for --samples samples at
h = T_s = 1e-4 s and times every sample with CLOCK_MONOTONIC: FMI 2.0 CS, FMI 3.0 CS, FMI 3.0 in
Event Mode, the clocked controller (TAPMP_ControllerClocked), and the control law alone
(tapmp_controller_sample, what the controller calls per sample), for each law SC-DC, APD-DC and
PID-DC (the `law` setting; every other setting at its default). The inputs are recorded from one
reference run (the paper scenario on the native FMI 2.0 FMUs, 2.5 s): the trajectory's outputs and
the plant's measured q and dq at every step, replayed cyclically. Prints p50, p99, p99.99 and max
in us and as a fraction of the cycle; writes them as JSON (default
benchmarks/results/controller_time.json).
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CYCLE_S = 1e-4          # the servo cycle T_s [s]
HOST = ROOT / "benchmarks" / "controller_time.c"
INPUTS = ("X_d", "Z_d", "B_d", "dX_d", "dZ_d", "dB_d", "ddX_d", "ddZ_d", "ddB_d", "q1", "q2", "q3", "dq1", "dq2", "dq3")
# variant: (host MODE, family folder, FMU)
VARIANTS = {"FMI 2.0 CS": ("fmi2", "fmi2", "TAPMP_Controller"),
            "FMI 3.0 CS": ("fmi3", "fmi3", "TAPMP_Controller"),
            "FMI 3.0 event mode": ("fmi3-event", "fmi3", "TAPMP_Controller"),
            "FMI 3.0 clocked": ("fmi3-clocked", "fmi3", "TAPMP_ControllerClocked"),
            "law alone": ("law", "fmi2", "TAPMP_Controller")}
LAWS = {"sc-dc": 0, "apd-dc": 1, "pid-dc": 2}   # the controller's `law` setting (tapmp/laws.py)
QUANTILES = {"p50": 50.0, "p99": 99.0, "p99.99": 99.99}


class BenchError(Exception):
    """A run that cannot be made (missing FMUs, a failed host): one line, exit code 2."""


def recorded_inputs(fmi2_ssp: Path, path: Path) -> int:
    """The controller's 15 inputs at every step of the paper scenario on ``fmi2_ssp`` (2.5 s, h = 1e-4 s)
    written to ``path`` as rows of doubles; returns the number of rows."""
    from orchestrator.engine.master import CoSimulation, RunOptions
    from orchestrator.tool.envelope import envelope
    from orchestrator.tool.roles import ROLES
    from orchestrator.tool.scenario import load
    sc = load(ROOT / "scenarios" / "paper_simulation.toml")
    with CoSimulation(fmi2_ssp, sc.parameters(), RunOptions(start_time=sc.start_time, step_size=sc.step,
                                                            ordering=sc.ordering, check=envelope(sc),
                                                            stepper="compiled", roles=ROLES)) as sim:
        rows = np.empty((sc.n_steps, len(sim.columns)))
        left = 0
        while left < sc.n_steps:
            left += sim.advance(rows[left:])
        columns = sim.columns
    # the controller's inputs are the outputs connected to them: trajectory pose, plant q and dq
    source = {n: (f"trajectory.{n}" if n.endswith("_d") else f"plant.{n}") for n in INPUTS}
    missing = [c for c in source.values() if c not in columns]
    if missing:
        raise BenchError(f"the reference run has no column {missing[0]} (columns: {', '.join(columns[:8])}, ...)")
    table = np.ascontiguousarray(rows[:, [columns.index(source[n]) for n in INPUTS]], dtype=np.float64)
    table.tofile(path)
    return len(table)


def settings_bytes(path: Path) -> None:
    """The controller's default settings (tapmp_controller_settings, filled by the C model's binding) as bytes
    into ``path``, for the host's `law` mode."""
    from tapmp.cmodel import load, settings
    ffi = load()[0]
    path.write_bytes(bytes(ffi.buffer(settings("TAPMP_Controller", {}))))


def compile_host(sources: Path, exe: Path) -> Path:
    """benchmarks/controller_time.c with the C model of the FMU sources folder ``sources``, compiled with the
    project's flags into ``exe``."""
    from ctoolchain import CFLAGS, compile_c
    from orchestrator.builder.build_native import fmi_headers_dir
    flags = [f for f in CFLAGS if f != "-fvisibility=hidden"]
    return compile_c([HOST, sources / "tapmp_model.c"], exe, shared=False, flags=flags,
                     includes=[fmi_headers_dir(), sources], libs=["dl", "m"])


def unzip(fmu: Path, dest: Path) -> Path:
    """``fmu`` extracted into ``dest`` (its shared libraries made loadable); returns ``dest``."""
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    for so in (dest / "binaries").glob("*/*.so"):
        so.chmod(0o755)
    return dest


def statistics(ns: np.ndarray) -> dict:
    """p50, p99, p99.99, max and mean of durations ``ns`` [ns], in us and as a fraction of the cycle."""
    us = ns.astype(np.float64) / 1e3
    out = {k: float(np.percentile(us, q)) for k, q in QUANTILES.items()}
    out["max"] = float(us.max())
    out["mean"] = float(us.mean())
    return {"us": out, "of_cycle": {k: v / (CYCLE_S * 1e6) for k, v in out.items()},
            "over_cycle": int(np.count_nonzero(us > CYCLE_S * 1e6))}


def native_fmus(native: Path) -> dict[str, Path]:
    """{variant: FMU path} from a folder laid out as build/native/ (BenchError naming what is missing)."""
    fmus = {}
    for variant, (_, family, model) in VARIANTS.items():
        fmu = native / family / f"{model}.fmu"
        if not fmu.is_file():
            raise BenchError(f"--native = {native} has no {family}/{model}.fmu: run `tapmp build` first or pass --build")
        fmus[variant] = fmu
    return fmus


def run(args, tmp: Path) -> dict:
    """Every variant and law timed; the result document."""
    native = Path(args.native)
    if args.build:
        from orchestrator.builder.build_native import build_native
        native = tmp / "native"
        build_native(native, families=("fmi2", "fmi3"), log=lambda *_: None, windows=False)
    fmus = native_fmus(native)
    units = {}
    for variant, fmu in fmus.items():
        if fmu not in units:
            units[fmu] = unzip(fmu, tmp / f"{len(units)}_{fmu.stem}")
    controller2 = units[fmus["FMI 2.0 CS"]]
    exe = compile_host(controller2 / "sources", tmp / "controller_time")
    inputs, settings = tmp / "inputs.bin", tmp / "settings.bin"
    n_rows = recorded_inputs(native / "fmi2" / "TAPMP.ssp", inputs)
    settings_bytes(settings)
    rows = []
    for variant in args.variants:
        mode, _, _ = VARIANTS[variant]
        path = settings if mode == "law" else units[fmus[variant]]
        for law in args.laws:
            out = tmp / "ns.bin"
            done = subprocess.run([str(exe), mode, str(path), str(inputs), str(args.samples), str(LAWS[law]), str(out)],
                                  capture_output=True, text=True)
            if done.returncode != 0:
                raise BenchError(f"{variant} {law}: the C host failed: {done.stderr.strip()}")
            ns = np.fromfile(out, dtype=np.int64)
            stats = statistics(ns)
            rows.append({"variant": variant, "law": law, "samples": len(ns), **stats})
            print(f"  {variant:20s} {law:7s} p50 {stats['us']['p50']:7.3f} us  max {stats['us']['max']:9.3f} us",
                  file=sys.stderr)
    return {"command": " ".join(["benchmarks/bench_controller_time.py", *args.argv]),
            "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "machine": {"platform": platform.platform(), "processor": cpu_name(), "cores": os.cpu_count(),
                        "load_average_1min": os.getloadavg()[0]},
            "samples": args.samples, "step_s": CYCLE_S, "cycle_us": CYCLE_S * 1e6, "clock": "CLOCK_MONOTONIC",
            "inputs": f"the paper scenario's controller inputs recorded on the native FMI 2.0 loop, {n_rows} rows "
                      "replayed cyclically",
            "rows": rows}


def cpu_name() -> str:
    """The processor's model name (Linux /proc/cpuinfo), else platform.processor()."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def table(doc: dict) -> str:
    """The result as a Markdown table: us, the p99.99 and max as a fraction of the 100 us cycle, and how many
    samples took longer than the cycle."""
    lines = ["| variant | law | p50 [us] | p99 [us] | p99.99 [us] | max [us] | p99.99 / cycle | max / cycle "
             "| samples over the cycle |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        us = r["us"]
        lines.append(f"| {r['variant']} | {r['law'].upper()} | {us['p50']:.2f} | {us['p99']:.2f} | {us['p99.99']:.2f} "
                     f"| {us['max']:.1f} | {r['of_cycle']['p99.99']:.3f} | {r['of_cycle']['max']:.2f} | {r['over_cycle']} |")
    return "\n".join(lines)


def positive_int(text: str) -> int:
    """argparse type: an integer in [1, 1e9]."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if not 1 <= n <= 1_000_000_000:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: allowed is an integer in [1, 1000000000]")
    return n


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=positive_int, default=1_000_000, help="timed samples per row (default 1e6)")
    ap.add_argument("--native", default=str(ROOT / "build" / "native"), help="the native FMUs (default build/native)")
    ap.add_argument("--build", action="store_true", help="build the native FMUs for this machine into a temporary folder")
    ap.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS), metavar="VARIANT",
                    help=f"default all: {', '.join(VARIANTS)}")
    ap.add_argument("--laws", nargs="+", choices=list(LAWS), default=list(LAWS), help="default all")
    ap.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "controller_time.json")
    args = ap.parse_args(argv)
    args.argv = argv
    try:
        with tempfile.TemporaryDirectory(prefix="tapmp_ctime_") as tmp:
            doc = run(args, Path(tmp))
    except BenchError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    args.json.parent.mkdir(parents=True, exist_ok=True)
    part = args.json.with_name(args.json.name + ".part")
    part.write_text(json.dumps(doc, indent=1) + "\n")
    part.replace(args.json)  # whole or not at all
    print(f"{doc['samples']} samples per row at h = {CYCLE_S * 1e6:g} us on {doc['machine']['processor']}")
    print(table(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
