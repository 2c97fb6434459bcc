"""Every script in benchmarks/ runs, in a smoke mode (a tiny horizon, one repeat), and prints
the figures it promises: the benchmarks cannot rot between the measurements in
docs/performance.md. The numbers themselves are not judged (a shared machine); their
presence, form and the invariants between them are."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # every benchmark script in its smoke mode

ROOT = Path(__file__).resolve().parents[2]
NUMBER = r"\d+(?:\.\d+)?"


def bench(script, *args, tmp_path, timeout=900):
    res = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), *map(str, args)], cwd=ROOT,
                         capture_output=True, text=True, timeout=timeout, env=dict(os.environ, TMPDIR=str(tmp_path)))
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout


def table(text: str, header: str) -> list[list[str]]:
    """The rows (split on runs of 2+ spaces) after the line starting with ``header``, up to a blank line
    or a line with another number of fields."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header)) + 1
    rows = []
    for line in lines[start:]:
        parts = re.split(r"\s{2,}", line.strip())
        if not line.strip() or len(parts) < 2 or (rows and len(parts) != len(rows[0])):
            break
        rows.append(parts)
    return rows


def test_every_script_in_benchmarks_has_a_smoke_test():
    tested = set(re.findall(r'bench\("(\w+\.py)"', Path(__file__).read_text()))
    scripts = {p.name for p in (ROOT / "benchmarks").glob("*.py")}
    assert scripts == tested


def test_bench_cosim_prints_every_configuration(built, tmp_path):
    out = bench("bench_cosim.py", "--stop-time", "0.005", "--repeat", "1", "--json", tmp_path / "c.json",
                tmp_path=tmp_path)
    rows = table(out, "configuration")
    configs = {(r[0], r[1]) for r in rows}
    kinds = ["full", "floor", "floor-pythonfmu", "full-native", "floor-native", "full-fmi3", "floor-fmi3",
             "full compiled", "full-native compiled", "full-fmi3 compiled", "plain", "c-master"]
    assert configs == {(k, o) for k in kinds for o in ("gauss-seidel", "jacobi")} | {("tapmp run (csv)",
                                                                                      "gauss-seidel")}
    for r in rows:
        us, wall, rtf = map(float, r[2:5])
        # 50 steps in 0.005 s simulated: wall = 50 us, RTF = wall / 0.005 (each printed rounded)
        assert us > 0 and rtf == pytest.approx(us * 50e-6 / 0.005, rel=0.01, abs=6e-4)
        assert wall == pytest.approx(us * 50e-6, abs=6e-4)
    report = json.loads((tmp_path / "c.json").read_text())
    assert report["steps"] == 50 and len(report["rows"]) == len(rows)
    assert re.search(rf"peak memory \(max RSS of this process\): {NUMBER} MiB", out)


def test_bench_peers_prints_tapmp_ecos_libcosim_and_the_c_loop(native_built, tmp_path):
    out = bench("bench_peers.py", "--ssp", native_built["fmi2"]["ssp"], "--stop-time", "0.01", "--repeat", "1",
                tmp_path=tmp_path)
    rows = table(out, "master")
    assert [r[0] for r in rows] == ["tapmp (Python loop)", "tapmp (compiled core)", "Ecos (ecospy)",
                                    "libcosim (libcosimpy)", "C loop, all outputs", "C loop (c_master.c)"]
    assert all(float(r[1]) > 0 for r in rows) and rows[-1][2] == "1.00"
    assert re.search(rf"^tapmp compiled core / Ecos: {NUMBER}$", out, re.M)


def test_bench_run_prints_the_cost_of_writing_each_format(native_built, tmp_path):
    out = bench("bench_run.py", "--ssp", native_built["fmi2"]["ssp"], "--stop-time", "0.05", "--repeat", "1",
                tmp_path=tmp_path)
    rows = table(out, "configuration")
    assert [r[0] for r in rows] == ["cosim", "run csv", "run mat"]
    assert rows[0][3] == "1.00"
    for r in rows[1:]:
        assert float(r[1]) > 0 and re.fullmatch(rf"results\.(csv|mat): {NUMBER} MB", r[4])


def test_bench_memory_prints_the_peak_of_two_runs(built, tmp_path):
    out = bench("bench_memory.py", "--ssp", built["ssp"], "--times", "0.02", "0.04", "--json", tmp_path / "m.json",
                tmp_path=tmp_path)
    rows = table(out, "simulated s")
    assert [(r[0], r[1]) for r in rows] == [("0.02", "200"), ("0.04", "400")]
    assert all(float(r[2]) > 10 for r in rows)  # MiB of a Python process with numpy
    assert re.search(rf"^peak memory 0.04 s / 0.02 s: {NUMBER}$", out, re.M)
    assert json.loads((tmp_path / "m.json").read_text())["runs"][1]["steps"] == 400


def test_throughput_prints_cases_per_minute_bytes_and_cpu_per_case_on_a_loopback_cluster(built, tmp_path):
    study = tmp_path / "tiny.toml"
    study.write_text(f'[study]\nname = "tiny"\nbase = "{ROOT / "scenarios" / "paper_simulation.toml"}"\n'
                     f'output = "{tmp_path / "out"}"\n[set]\nstop_time = 0.01\n'
                     '[grid]\n"gain_overrides.D" = [450.0, 900.0]\n')
    out = bench("throughput.py", "--study", study, "--ssp", built["ssp"], "--workers", "1", tmp_path=tmp_path)
    assert "loopback cluster (dask scheduler + dask worker)" in out
    m = re.search(rf"^\| 1 \| 2 \| ({NUMBER}) \| ({NUMBER}) \| x1.00 \| ({NUMBER}) \| ({NUMBER}) \| ({NUMBER}) "
                  rf"\| ({NUMBER}) \| {NUMBER} \|$", out, re.M)
    assert m, out
    wall, rate, received, client, scheduler, worker = map(float, m.groups())
    # rate = 2 cases / the wall time, which is printed rounded to 0.1 s
    assert 120 / (wall + 0.05) <= rate * 1.001 and (wall <= 0.05 or rate <= 120 / (wall - 0.05) * 1.001)
    # every case's run.json and metrics.json came back (compressed); every process worked for them
    assert received > 200 and client > 0 and scheduler > 0 and worker > 0


def test_bench_case_prints_the_cpu_per_case_with_fmus_kept_loaded_and_loaded_per_case(native_built, tmp_path):
    out = bench("bench_case.py", "--ssp", native_built["fmi2"]["ssp"], "--cases", "2", "--stop-time", "0.01",
                "--profile", tmp_path=tmp_path)
    rows = table(out, "mode")
    assert [r[0] for r in rows] == ["kept loaded, reset", "loaded per case"] and all(r[1] == "2" for r in rows)
    assert all(float(r[2]) > 0 and float(r[3]) > 0 for r in rows)
    assert "run_case" in out and "cumulative" in out  # the profile of the kept mode
    assert not list(tmp_path.glob("tapmp_cosim_*")) and not list(tmp_path.glob("tapmp_case_*"))


def test_bench_loop_prints_both_loops_and_the_same_doubles(tmp_path):
    out = bench("bench_loop.py", "--stop-time", "0.005", "--repeat", "1", tmp_path=tmp_path)
    rows = table(out, "loop")
    assert [r[0] for r in rows] == ["python", "compiled"] and all(float(r[1]) > 0 for r in rows)
    assert "same doubles: yes" in out.splitlines()
    m = re.search(rf"^python / compiled: ({NUMBER})$", out, re.M)
    # the ratio of the times per step (printed to 0.01 us; the wall times to 1 ms are too coarse here)
    assert m and float(m.group(1)) == pytest.approx(float(rows[0][2]) / float(rows[1][2]), rel=0.03, abs=0.1)



def test_bench_event_mode_prints_both_loops_per_system_and_the_same_doubles(native_built, tmp_path):
    fmi3 = native_built["fmi3"]
    out = bench("bench_event_mode.py", "--ssp", fmi3["ssp"], fmi3["clocked_ssp"], "--steps", "50", "--repeat", "1",
                tmp_path=tmp_path)
    for name in ("TAPMP.ssp", "TAPMP_Clocked.ssp"):
        assert re.search(rf"^{re.escape(name)}: python {NUMBER} us, compiled {NUMBER} us per macro step$", out, re.M)
    assert "same doubles: yes" in out.splitlines()

def test_reference_run_regenerates_the_stored_reference_bit_for_bit(tmp_path):
    out = bench("reference_run.py", "--out", tmp_path / "ref.csv", tmp_path=tmp_path)
    assert out.strip() == f"wrote {tmp_path / 'ref.csv'}"
    assert (tmp_path / "ref.csv").read_bytes() == (ROOT / "tests" / "data" / "reference_run.csv").read_bytes()


def test_bench_compare_prints_compare_against_one_run(native_built, tmp_path):
    out = bench("bench_compare.py", "--ssp", native_built["fmi2"]["ssp"], "--stop-time", "0.02", "--repeat", "1",
                tmp_path=tmp_path)
    rows = table(out, "command")
    assert [r[0] for r in rows] == ["tapmp run", "tapmp compare", "tapmp compare --no-figures",
                                    "tapmp compare --no-noise"]
    assert all(float(r[1]) > 0 for r in rows)
    # the ratios of the printed (rounded) times: as close as their last digits allow
    for label, row in (("compare", rows[1]), ("compare --no-figures", rows[2]), ("compare --no-noise", rows[3])):
        m = re.search(rf"^{label} / run: ({NUMBER})$", out, re.M)
        assert m and float(m.group(1)) == pytest.approx(float(row[1]) / float(rows[0][1]), rel=0.03)


def test_bench_compare_times_the_stages_of_a_comparison(native_built, tmp_path):
    out = bench("bench_compare.py", "--stages", "--ssp", native_built["fmi2"]["ssp"], "--stop-time", "0.02",
                "--jobs", "1", tmp_path=tmp_path)
    rows = dict(table(out, "stage"))
    assert list(rows) == ["imports", "stability checks", "runs", "figures", "figures during the runs",
                          "whole comparison"]
    parts = sum(float(rows[k]) for k in ("stability checks", "runs", "figures"))
    assert 0 < parts <= float(rows["whole comparison"]) + 0.02
    assert 0 <= float(rows["figures during the runs"]) <= float(rows["figures"])


def test_bench_reproduce_prints_the_tour_command_against_one_run(native_built, tmp_path):
    out = bench("bench_reproduce.py", "--repeat", "1", "--stop-time", "0.02", "--paper-gains-stop-time", "0.0005",
                "--ssp", native_built["fmi2"]["ssp"], tmp_path=tmp_path)
    rows = table(out, "command")
    assert [r[0] for r in rows] == ["tapmp run", "tapmp reproduce"]
    for _, wall, cpu, load in rows:
        assert float(wall) > 0 and float(cpu) > 0 and float(load) >= 0
    m = re.search(rf"^reproduce / run: ({NUMBER})$", out, re.M)
    assert m and float(m.group(1)) == pytest.approx(float(rows[1][1]) / float(rows[0][1]), rel=0.03, abs=0.05)


def test_bench_quick_start_prints_the_build_time_and_the_load(tmp_path):
    out = bench("bench_quick_start.py", "--warm-only", tmp_path=tmp_path)
    assert out.splitlines()[0] == f"bash build_fmus.sh --host on {os.cpu_count()} cores"
    rows = table(out, "cache ")
    assert [r[0] for r in rows] == ["warm"] and all(re.fullmatch(NUMBER, v) for v in rows[0][1:])


def test_bench_controller_time_writes_ordered_positive_statistics_for_every_variant_and_law(native_built, tmp_path):
    native = native_built["fmi2"]["ssp"].parent.parent
    out = bench("bench_controller_time.py", "--native", native, "--samples", "2000", "--json", tmp_path / "t.json",
                tmp_path=tmp_path)
    report = json.loads((tmp_path / "t.json").read_text())
    variants = ["FMI 2.0 CS", "FMI 3.0 CS", "FMI 3.0 event mode", "FMI 3.0 clocked", "law alone"]
    assert [(r["variant"], r["law"]) for r in report["rows"]] == [(v, law) for v in variants
                                                                 for law in ("sc-dc", "apd-dc", "pid-dc")]
    assert report["samples"] == 2000 and report["cycle_us"] == 100.0 and report["clock"] == "CLOCK_MONOTONIC"
    for r in report["rows"]:
        us = r["us"]
        assert r["samples"] == 2000
        assert all(0 < v < float("inf") for v in us.values())
        assert us["p50"] <= us["p99"] <= us["p99.99"] <= us["max"]
        assert r["of_cycle"]["max"] == pytest.approx(us["max"] / 100.0)
        assert 0 <= r["over_cycle"] <= 2000
    assert len([line for line in out.splitlines() if line.startswith("| FMI ") or line.startswith("| law ")]) == 15


@pytest.mark.interop
@pytest.mark.needs_shared("tools/OMSimulator/bin/OMSimulator")
def test_bench_real_time_peers_measures_every_tool_with_one_probe_stamp_per_dostep(native_built, tmp_path):
    from tests.support.shared import shared
    out = bench("bench_real_time_peers.py", "--ssp", native_built["fmi2"]["ssp"], "--stop-time", "0.02",
                "--oms-stop-time", "0.005", "--factors", "1", "--free", "--records", tmp_path / "records",
                "--json", tmp_path / "p.json", "--oms", shared("tools/OMSimulator/bin/OMSimulator"), tmp_path=tmp_path)
    report = json.loads((tmp_path / "p.json").read_text())
    tools = ["OMSimulator", "Ecos", "libcosim", "tapmp"]
    assert [(r["tool"], r["factor"]) for r in report["rows"]] == [(t, f) for f in (None, 1.0) for t in tools]
    for r in report["rows"]:
        if r["tool"] == "tapmp" and r["factor"]:
            continue
        assert r["available"], r
        stamps = np.loadtxt(r["record"], ndmin=2)
        t, h, wall = stamps[:, 0], stamps[:, 1], stamps[:, 2]
        # one line per doStep: each starts where the one before ended, over the simulated horizon
        assert len(stamps) == r["probe"]["steps"]
        np.testing.assert_allclose(t[1:], t[:-1] + h[:-1], rtol=0, atol=1e-12)
        assert t[0] == 0.0 and t[-1] + h[-1] == pytest.approx(r["stop_time_s"], abs=STEP_TOLERANCE)
        assert np.all(np.diff(wall) >= 0) and np.all(h > 0)
        assert r["probe"]["achieved_factor"] > 0
        if r["factor"]:
            late = r["probe"]["lateness_s"]
            assert late["p50"] <= late["p99"] <= late["p999"] <= late["max"]
            assert 0 <= r["probe"]["overruns"] < len(stamps)
    tapmp = report["rows"][-1]
    if not tapmp["available"]:  # before `tapmp run --real-time` exists: said so, not measured
        assert tapmp["why"] == "this tapmp has no `tapmp run --real-time`"
        assert "| tapmp | 1 | - | - | not available |" in out
    else:
        assert set(tapmp["run_json"]) >= {"factor", "lateness_s", "achieved_factor", "overruns"}
    assert out.count("\n| ") == 1 + len(report["rows"])  # the table's header and one row per run


STEP_TOLERANCE = 1.1e-4  # a tool may stop one macro step short of a horizon its summed clock does not reach


def test_bench_real_time_prints_every_case(native_built, tmp_path):
    out = bench("bench_real_time.py", "--ssp", native_built["fmi2"]["ssp"], "--seconds", "0.02", "--load", "1",
                tmp_path=tmp_path)
    rows = table(out, "machine")
    assert [(r[0], r[1], r[2]) for r in rows] == [(m, f, "other") for m in ("idle", "loaded") for f in ("1", "10")]
    for r in rows:
        late = [float(v) for v in r[4:8]]
        assert late == sorted(late) and int(r[3]) == 200 * int(r[1])  # p50 <= p99 <= p99.9 <= max; the steps
        assert 0 < float(r[11]) <= int(r[1]) and int(r[9]) >= int(r[10]) >= 0
    m = re.search(rf"^recording a block of 1000 rows .*: min ({NUMBER}) ms, median ({NUMBER}) ms, max ({NUMBER}) ms "
                  r"of 10 blocks$", out, re.M)
    assert m and 0 < float(m.group(1)) <= float(m.group(2)) <= float(m.group(3))


@pytest.mark.parametrize("where", [[], ["--remote"]], ids=["local", "remote"])
def test_bench_study_scale_prints_cases_per_second_cpu_per_case_and_the_batch_size(native_built, tmp_path, where):
    out = bench("bench_study_scale.py", "--ssp", native_built["fmi2"]["ssp"], "--short", "24", "--paper", "8",
                "--short-stop", "0.01", "--paper-stop", "0.02", *where, tmp_path=tmp_path)
    assert ("loopback scheduler" in out.splitlines()[0]) == bool(where)
    found = re.findall(rf"^\| (short|paper) \| (\d+) \| ({NUMBER}) \| ({NUMBER}) \| ({NUMBER}) \| (\d+) \| {NUMBER} "
                       rf"\| ({NUMBER}) \| ({NUMBER}) \| ({NUMBER}) \| {NUMBER} \|$", out, re.M)
    assert [f[:3] for f in found] == [("short", "24", "0.01"), ("paper", "8", "0.02")], out
    for _, n, _, wall, rate, batch, main_ms, process_ms, worker_ms in found:
        # the automatic size: n / (4 batches x 2 workers), less than a second of work
        assert int(batch) == int(n) // 8
        n, wall, rate = int(n), float(wall), float(rate)  # rate = n / the wall time, printed rounded to 0.1 s
        assert n / (wall + 0.05) <= rate * 1.01 and (wall <= 0.05 or rate <= n / (wall - 0.05) * 1.01)
        assert 0 < float(main_ms) <= float(process_ms) and float(worker_ms) > 0
    estimates = re.findall(r"^\| (short|paper) \| [\d.]+ \| \d+ \| \d+ \| \d+ \| the (?:client|workers) \|$", out,
                           re.M)
    assert estimates == ["short", "paper"], out
