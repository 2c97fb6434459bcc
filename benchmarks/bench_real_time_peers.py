"""Real time beside other tools: the same SSP on the same machine, in one run, paced to the wall clock by
OMSimulator (--realTime), Ecos (ecos simulate --rtf), libcosim (libcosimpy's real-time setting) and
`tapmp run --real-time`. Run from the repository root after `tapmp build`:

    .venv/bin/python benchmarks/bench_real_time_peers.py [--stop-time 0.2] [--factors 1 10] [--json PATH]

Each tool runs a copy of the SSP (default build/native/fmi2/TAPMP.ssp) with one more component, the probe
FMU (benchmarks/probe/probe_fmu.c), connected to nothing: it notes the wall time (CLOCK_MONOTONIC) of each
doStep. From its record, the same for every tool: the lateness of each doStep against the schedule
t0_wall + (t - t0) / factor (t0_wall = the first doStep; negative = early), the achieved real-time factor
(simulated time / wall time from the first to the last doStep) and the overruns (doSteps more than one macro
step h / factor late). Beside it, what the tool itself reports, where it reports something: Ecos's last
"actual RTF", libcosim's execution status (real_time_factor), tapmp's run.json "real_time". A tool that
does not offer a factor (OMSimulator: real time or not) or an option (`tapmp run` without --real-time)
gets a row saying so. With --free, each tool also runs unpaced first: the factor it reaches at most,
beside which a target factor it misses reads plainly. OMSimulator runs --oms-stop-time (default 0.02 s) instead of --stop-time: its
experimental real-time mode takes longer for each step than the one before (see docs/performance.md).
Writes the rows as JSON (default benchmarks/results/real_time_peers.json) and prints a table.
"""

import argparse
import gc
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from probe.probe import build_probe, lateness, read_record, with_probe  # noqa: E402

STEP = 1e-4   # the SSP's macro step [s]
OMS = ROOT.parent / "shared" / "tools" / "OMSimulator" / "bin" / "OMSimulator"
TOOLS = ("OMSimulator", "Ecos", "libcosim", "tapmp")


class NotAvailable(Exception):
    """The tool does not offer this run (a factor, an option): the row says why."""


def run_omsimulator(ssp: Path, stop: float, factor: float, work: Path, oms: Path) -> dict:
    """OMSimulator --realTime=true (real time only: it has no factor); without it if ``factor`` is None."""
    if factor not in (None, 1):
        raise NotAvailable("OMSimulator's --realTime has no factor (real time or as fast as it can)")
    if not oms.is_file():
        raise NotAvailable(f"no OMSimulator at {oms}")
    done = subprocess.run([str(oms), f"--tempDir={work}", f"--resultFile={work / 'r.csv'}", "--mode=cs",
                           f"--stopTime={stop}", f"--stepSize={STEP}", *(["--realTime=true"] if factor else []),
                           str(ssp)],
                          cwd=work, capture_output=True, text=True, timeout=900)
    if done.returncode != 0 or re.search(r"^error:", done.stdout, re.M):
        raise RuntimeError(f"OMSimulator failed: {(done.stdout + done.stderr).strip().splitlines()[-1:]}")
    return {"reports": "nothing on real time"}


def ecos_program(work: Path) -> Path:
    """Ecos's command-line program from the ecospy package (its wheel ships it without the execute bit),
    copied into ``work`` with proxyfmu beside it and made executable."""
    import ecospy
    binaries = Path(ecospy.__file__).parent / "binaries"
    for name in ("ecos", "proxyfmu"):
        shutil.copy(binaries / name, work / name)
        (work / name).chmod(0o755)
    return work / "ecos"


def run_ecos(ssp: Path, stop: float, factor: float, work: Path) -> dict:
    """ecos simulate --rtf FACTOR (-1, no pacing, if ``factor`` is None); its own last "actual RTF" line."""
    done = subprocess.run([str(ecos_program(work)), "simulate", "--path", str(ssp), "--stopTime", repr(stop),
                           "--stepSize", repr(STEP), "--rtf", repr(factor or -1.0), "--noCsv"],
                          cwd=work, capture_output=True, text=True, timeout=900,
                          env={**os.environ, "TMPDIR": str(work)})  # Ecos unpacks the SSP into the temp folder: ours
    if done.returncode != 0:
        raise RuntimeError(f"Ecos failed: {(done.stdout + done.stderr).strip().splitlines()[-1:]}")
    actual = re.findall(r"actual RTF=([0-9.eE+-]+)", done.stdout + done.stderr)
    return {"reports": f"actual RTF {actual[-1]} (its last progress line)" if actual else "no RTF line",
            "tool_factor": float(actual[-1]) if actual else None}


def run_libcosim(ssp: Path, stop: float, factor: float, work: Path) -> dict:
    """libcosimpy: real_time_simulation_enabled(True), real_time_factor_target(factor), simulate_until(stop) (no
    real-time setting if ``factor`` is None)."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(ssp), step_size=round(STEP * 1e9))
    if factor and not (execution.real_time_simulation_enabled(True) and execution.real_time_factor_target(factor)):
        raise RuntimeError("libcosim refused the real-time setting")
    if not execution.simulate_until(round(stop * 1e9)):
        raise RuntimeError("libcosim: simulate_until failed")
    status = execution.status()
    out = {"reports": f"real_time_factor {status.real_time_factor:.4f} (execution status)",
           "tool_factor": float(status.real_time_factor)}
    del execution, status
    gc.collect()  # the execution frees its FMUs here: the probe writes its record at fmi2FreeInstance
    return out


def run_tapmp(ssp: Path, stop: float, factor: float, work: Path) -> dict:
    """tapmp run --real-time FACTOR on the paper scenario (without the option if ``factor`` is None); run.json's
    "real_time"."""
    out = work / "run"
    done = subprocess.run([sys.executable, "-c", "import sys; from orchestrator.cli import main; sys.exit(main())", "run",
                           str(ROOT / "scenarios" / "paper_simulation.toml"),
                           "--ssp", str(ssp), "--set", f"stop_time={stop!r}", "--out", str(out), "--no-progress",
                           *(["--real-time", repr(factor)] if factor else [])], cwd=ROOT, capture_output=True, text=True, timeout=900)
    if done.returncode != 0 and "--real-time" in done.stderr and "unrecognized" in done.stderr:
        raise NotAvailable("this tapmp has no `tapmp run --real-time`")
    if done.returncode != 0:
        raise RuntimeError(f"tapmp run failed: {done.stderr.strip().splitlines()[-1:]}")
    if not factor:
        return {"reports": "nothing on real time without --real-time"}
    real_time = json.loads((out / "run.json").read_text()).get("real_time")
    if not real_time:
        raise RuntimeError("tapmp run --real-time wrote no \"real_time\" into run.json")
    return {"reports": f"achieved_factor {real_time['achieved_factor']:.4f} (run.json)",
            "tool_factor": float(real_time["achieved_factor"]), "run_json": real_time}


def one(tool: str, ssp: Path, factor: float, args, tmp: Path) -> dict:
    """One tool at one factor: its row (probe statistics, what the tool reports, wall seconds), or why not."""
    label = f"{factor:g}" if factor else "free"
    work = tmp / f"{tool}_{label}"
    work.mkdir()
    record = (Path(args.records) if args.records else work) / f"{tool}_{label}.txt"
    record.parent.mkdir(parents=True, exist_ok=True)
    probed = with_probe(ssp, build_probe(work / "TAPMP_Probe.fmu", record), work / "TAPMP_probe.ssp")
    stop = args.oms_stop_time if tool == "OMSimulator" else args.stop_time
    row = {"tool": tool, "factor": factor, "stop_time_s": stop}
    start = time.perf_counter()
    try:
        if tool == "OMSimulator":
            row.update(run_omsimulator(probed, stop, factor, work, Path(args.oms)))
        elif tool == "Ecos":
            row.update(run_ecos(probed, stop, factor, work))
        elif tool == "libcosim":
            row.update(run_libcosim(probed, stop, factor, work))
        else:
            row.update(run_tapmp(probed, stop, factor, work))
    except NotAvailable as why:
        return {**row, "available": False, "why": str(why)}
    row["wall_s"] = time.perf_counter() - start
    rows = read_record(record)
    # as fast as it can: no schedule to be late against, only the factor it reaches
    row["probe"] = lateness(rows, factor) if factor else {"steps": len(rows), **_free(rows)}
    row["record"] = str(record) if args.records else None
    return {**row, "available": True}


def _free(rows) -> dict:
    """The achieved real-time factor of a run paced by nothing (simulated / wall time, first to last doStep)."""
    return {"achieved_factor": lateness(rows, 1.0)["achieved_factor"]}


def table(doc: dict) -> str:
    """The rows as a Markdown table (lateness in ms)."""
    lines = ["| tool | factor | simulated [s] | doSteps | achieved factor (probe) | lateness p50 / p99 / max [ms] "
             "| overruns | the tool reports |", "|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        factor = f"{r['factor']:g}" if r["factor"] else "none (as fast as it can)"
        if not r["available"]:
            lines.append(f"| {r['tool']} | {factor} | - | - | not available | - | - | {r['why']} |")
            continue
        p = r["probe"]
        if not r["factor"]:
            lines.append(f"| {r['tool']} | {factor} | {r['stop_time_s']:g} | {p['steps']} | {p['achieved_factor']:.4f} "
                         f"| - | - | {r['reports']} |")
            continue
        late = p["lateness_s"]
        lines.append(f"| {r['tool']} | {factor} | {r['stop_time_s']:g} | {p['steps']} | {p['achieved_factor']:.4f} "
                     f"| {late['p50'] * 1e3:.3f} / {late['p99'] * 1e3:.3f} / {late['max'] * 1e3:.3f} | {p['overruns']} "
                     f"| {r['reports']} |")
    return "\n".join(lines)


def positive(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        x = float(text)
    except ValueError:
        x = float("nan")
    if not 0 < x < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: allowed is a number > 0")
    return x


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ssp", type=Path, default=ROOT / "build" / "native" / "fmi2" / "TAPMP.ssp")
    ap.add_argument("--stop-time", type=positive, default=0.2, help="simulated seconds (default 0.2)")
    ap.add_argument("--oms-stop-time", type=positive, default=0.02, help="OMSimulator's simulated seconds (default 0.02)")
    ap.add_argument("--factors", type=positive, nargs="+", default=[1.0, 10.0], help="real-time factors (default 1 10)")
    ap.add_argument("--free", action="store_true", help="also each tool without pacing: the factor it can reach")
    ap.add_argument("--tools", nargs="+", choices=TOOLS, default=list(TOOLS))
    ap.add_argument("--oms", default=str(OMS), help="the OMSimulator program (default ../shared/tools/...)")
    ap.add_argument("--records", help="keep each probe's record in this folder (default: deleted)")
    ap.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "real_time_peers.json")
    args = ap.parse_args(argv)
    if not args.ssp.is_file():
        print(f"error: --ssp = {args.ssp} does not exist: run `tapmp build` first", file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory(prefix="tapmp_rtpeers_") as tmp:
        for factor in ([None] if args.free else []) + args.factors:
            for tool in args.tools:
                row = one(tool, args.ssp, factor, args, Path(tmp))
                rows.append(row)
                said = row["why"] if not row["available"] else f"achieved {row['probe']['achieved_factor']:.4f}"
                print(f"  {tool} x{factor or 'free'}: {said}", file=sys.stderr)
    doc = {"command": " ".join(["benchmarks/bench_real_time_peers.py", *argv]),
           "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "ssp": str(args.ssp), "step_s": STEP,
           "clock": "CLOCK_MONOTONIC (the probe FMU)",
           "machine": {"platform": platform.platform(), "cores": os.cpu_count(), "load_average_1min": os.getloadavg()[0]},
           "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    part = args.json.with_name(args.json.name + ".part")
    part.write_text(json.dumps(doc, indent=1) + "\n")
    part.replace(args.json)
    print(f"{args.ssp.name} with the probe FMU, macro step {STEP:g} s")
    print(table(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
