"""Studies on a real Dask LocalCluster through the real FMUs: rows, failures, resume, tuning."""

import csv
import json
import math
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.tool.scenario import ScenarioError, load, load_gain_file
from orchestrator.studies.run import run_study
from orchestrator.studies.study import StudyError, cases, load_study, read_study_csv
from tests.support.studies import client, write_study  # noqa: F401 (client is a fixture)

pytestmark = pytest.mark.slow  # studies on a real Dask LocalCluster

ROOT = Path(__file__).resolve().parents[2]
BASE = ROOT / "scenarios" / "paper_simulation.toml"


def rows_of(out: Path) -> dict:
    return {r["case"]: r for r in read_study_csv(out / "study.csv")}


def test_grid_study_writes_one_row_per_case_with_the_metrics_of_its_run(built, client, tmp_path):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n'
                       '"gain_overrides.Lambda_v" = [0.36, 0.72]\n')
    summary = run_study(load_study(path), built["ssp"], client, progress=False)
    assert summary["cases"] == 4 and summary["counts"]["completed"] == 4
    rows = rows_of(tmp_path / "out")
    assert sorted(rows) == ["c0000", "c0001", "c0002", "c0003"]
    assert [(rows[c]["law"], rows[c]["gain_overrides.Lambda_v"]) for c in sorted(rows)] == [
        ("sc-dc", 0.36), ("sc-dc", 0.72), ("apd-dc", 0.36), ("apd-dc", 0.72)]
    for case, row in rows.items():
        metrics = json.loads((tmp_path / "out" / "cases" / case / "metrics.json").read_text())
        run = json.loads((tmp_path / "out" / "cases" / case / "run.json").read_text())
        assert run["status"] == "completed" and run["scenario"]["law"] == row["law"]
        assert run["scenario"]["gain_values"]["Lambda_v"] == [row["gain_overrides.Lambda_v"]] * 3
        assert row["tracking_mae_um_1"] == pytest.approx(metrics["tracking_mae_um"][0], rel=1e-12)
        assert row["objective"] == pytest.approx(
            (sum(metrics["tracking_mae_um"]) + sum(metrics["sync_mae_um"])) / 6, rel=1e-12)
        assert 0.0 < row["objective"] < 1.0 and 0.9 < row["spectral_radius"] < 1.0
        assert row["wall_time_s"] > 0.0 and not (tmp_path / "out" / "cases" / case / "results.csv").exists()
    # twice the velocity gain, lower tracking error, for both laws
    assert rows["c0001"]["tracking_mae_um_mean"] < rows["c0000"]["tracking_mae_um_mean"]
    assert rows["c0003"]["tracking_mae_um_mean"] < rows["c0002"]["tracking_mae_um_mean"]
    assert (tmp_path / "out" / "sweep.png").stat().st_size > 10_000


def test_a_diverging_case_is_a_failed_row_and_the_others_complete(built, client, tmp_path):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n"plant.force_limit" = 0.0\n'
                       '[grid]\ngains = ["default", "paper_simulation", "paper_experiment"]\n')
    summary = run_study(load_study(path), built["ssp"], client, progress=False)
    rows = rows_of(tmp_path / "out")
    assert rows["c0000"]["status"] == "completed" and rows["c0000"]["objective"] < 1.0
    for case in ("c0001", "c0002"):
        error = rows[case]["error"]  # caught by the master's envelope (diverged) or by the plant's domain check
        assert (rows[case]["status"], "is outside the envelope" in error) in (("diverged", True), ("failed", False))
        assert "is outside the envelope" in error or "|B| < pi/2" in error, error
        assert rows[case]["objective"] is None and rows[case]["spectral_radius"] > 1.0
        run = json.loads((tmp_path / "out" / "cases" / case / "run.json").read_text())
        assert run["status"] == "failed" and run["failed_at_s"] < 0.002


def test_resume_runs_only_the_cases_without_a_row(built, client, tmp_path):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\n"gain_overrides.D" = [450.0, 900.0, 1800.0, 3600.0]\n')
    study = load_study(path)
    run_study(study, built["ssp"], client, progress=False)
    table = tmp_path / "out" / "study.csv"
    lines = table.read_text().splitlines(keepends=True)
    kept = {r["case"]: r for r in csv.DictReader(lines[:3])}  # header and two rows: as if interrupted
    table.write_text("".join(lines[:3]))
    with pytest.raises(StudyError, match="--resume"):
        run_study(study, built["ssp"], client, progress=False)
    summary = run_study(study, built["ssp"], client, resume=True, progress=False)
    assert summary["ran"] == 2 and summary["counts"]["completed"] == 4
    after = list(csv.DictReader(table.open()))
    assert sorted(r["case"] for r in after) == ["c0000", "c0001", "c0002", "c0003"]
    for r in after:
        if r["case"] in kept:
            assert r == kept[r["case"]]  # untouched, not run again
    assert len(after) == 4
    # a changed study is refused on resume
    path.write_text(path.read_text().replace("3600.0", "7200.0"))
    with pytest.raises(StudyError, match="different study"):
        run_study(load_study(path), built["ssp"], client, resume=True, progress=False)


def test_monte_carlo_draws_are_seeded_and_relative_factors_scale_the_base_values(tmp_path):
    text = ('[set]\nstop_time = 0.02\n[monte_carlo]\nsamples = 5\nseed = 7\n'
            '[monte_carlo.vary.mass]\ntargets = ["plant.m_1", "plant.m_3"]\ndistribution = "uniform"\n'
            'low = 0.8\nhigh = 1.2\nrelative = true\n'
            '[monte_carlo.vary.res]\ntargets = ["plant.encoder_resolution"]\ndistribution = "loguniform"\n'
            'low = 5e-8\nhigh = 5e-7\n')
    a, b = cases(load_study(write_study(tmp_path, text))), cases(load_study(write_study(tmp_path, text, "t")))
    assert a == b and len(a) == 5
    for c in a:
        f = c["params"]["mass"]
        assert 0.8 <= f <= 1.2 and 5e-8 <= c["params"]["res"] <= 5e-7
        assert c["changes"]["plant.m_1"] == pytest.approx(4.776 * f) and c["changes"]["plant.m_3"] == pytest.approx(4.775 * f)
        assert c["changes"]["plant.encoder_resolution"] == c["params"]["res"]
    assert len({c["params"]["mass"] for c in a}) == 5


@pytest.mark.parametrize("text, message", [
    ('[grid]\n"plant.mass" = [1.0]\n', "plant.mass is unknown"),
    ('[grid]\n"gain_overrides.D" = []\n', "non-empty list"),
    ('[monte_carlo]\nsamples = 3\n[monte_carlo.vary.x]\ntargets = ["plant.m_p"]\ndistribution = "gauss"\n', "seed"),
    ('[monte_carlo]\nsamples = 3\nseed = 1\n[monte_carlo.vary.x]\ntargets = ["plant.m_p"]\ndistribution = "gauss"\n',
     "distribution = 'gauss' is invalid: allowed are uniform, loguniform, normal"),
    ('[set]\nstop_time = -1.0\n[grid]\nlaw = ["sc-dc"]\n', "stop_time = -1.0 is invalid"),
    ('[tune]\nlaws = ["apd-dc"]\nwrite_to = "x"\n[tune.bounds.apd-dc]\nD = [1.0, 2.0]\n', "does not use b or D"),
    ('[tune]\nlaws = ["sc-dc"]\nwrite_to = "x"\n[tune.bounds.sc-dc]\nD = [0.0, 2.0]\n', "0 < low < high"),
    ("", "nothing varies"),
])
def test_invalid_study_files_are_refused_with_the_key_and_what_is_allowed(tmp_path, text, message):
    with pytest.raises(StudyError, match=message.replace("(", r"\(").replace("[", r"\[")):
        load_study(write_study(tmp_path, text))


def test_study_command_says_when_the_ssp_is_missing(tmp_path, capsys):
    path = write_study(tmp_path, '[grid]\nlaw = ["sc-dc"]\n')
    assert main(["study", str(path), "--ssp", str(tmp_path / "none.ssp"), "--workers", "1"]) == 2
    assert "build the FMUs first" in capsys.readouterr().err


def test_tuning_on_a_short_horizon_improves_the_objective_and_writes_a_usable_preset(built, client, tmp_path):
    text = ('[set]\nstop_time = 0.03\n[tune]\nlaws = ["sc-dc"]\npopulation = 4\ngenerations = 2\nseed = 3\n'
            f'write_to = "{tmp_path / "tuned"}"\ncompare_stop_time = 0.05\nms_bound = 3.0\n'
            '[tune.bounds.sc-dc]\nLambda_v = [0.05, 30.0]\nD = [100.0, 5000.0]\n')
    summary = run_study(load_study(write_study(tmp_path, text)), built["ssp"], client, progress=False,
                        command="tapmp study s.toml", write_docs=True)
    assert summary["write_to"] == tmp_path / "tuned" and not (tmp_path / "out" / "tuning").exists()
    r = summary["tuning"]["sc-dc"]
    assert r["evaluations"] == 4 * 2 * 3  # population x dimensions x (1 + generations)
    assert r["tuned"] < 0.9 * r["start"]
    rows = sorted((row for row in read_study_csv(tmp_path / "out" / "study.csv") if row["case"].startswith("sc-dc-")),
                  key=lambda row: row["case"])
    assert len(rows) == r["evaluations"]
    assert rows[0]["Lambda_v"] == pytest.approx(0.36) and rows[0]["D"] == pytest.approx(900.0)  # the start
    assert rows[0]["objective"] == pytest.approx(r["start"])
    rejected = [row for row in rows if row["status"] == "rejected"]
    assert rejected and all("above tune.ms_bound = 3" in row["error"] or row["spectral_radius"] >= 1.0
                            for row in rejected)
    assert all(not (tmp_path / "out" / "cases" / row["case"]).exists() for row in rejected)
    best = min((row for row in rows if row["status"] == "completed"), key=lambda row: row["objective"])
    preset = load_gain_file(tmp_path / "tuned" / "sc-dc.toml")
    assert preset["Lambda_v"] == (best["Lambda_v"],) * 3 and preset["Lambda_p"] == (300.0,) * 3
    scenario_file = tmp_path / "tuned.toml"
    scenario_file.write_text(BASE.read_text().replace('gains = "default"', 'gains_file = "tuned/sc-dc.toml"'))
    assert load(scenario_file).gain_values().D == (best["D"],) * 3
    compare = {row["case"]: row for row in read_study_csv(tmp_path / "out" / "study.csv")}
    assert compare["compare-sc-dc-tuned"]["objective"] < compare["compare-sc-dc-start"]["objective"]
    assert (tmp_path / "tuned" / "objective.png").stat().st_size > 10_000
    assert "| sc-dc | 24 |" in (tmp_path / "tuned" / "comparison.md").read_text()


def test_tuning_without_write_docs_writes_into_the_output_folder_and_leaves_write_to_alone(built, client, tmp_path):
    text = ('[set]\nstop_time = 0.01\n[tune]\nlaws = ["apd-dc"]\npopulation = 2\ngenerations = 1\nseed = 3\n'
            f'write_to = "{tmp_path / "docs"}"\ncompare_stop_time = 0.01\n'
            '[tune.bounds.apd-dc]\nLambda_v = [0.1, 1.0]\n')
    summary = run_study(load_study(write_study(tmp_path, text)), built["ssp"], client, progress=False)
    tuned = tmp_path / "out" / "tuning"
    assert summary["write_to"] == tuned and not (tmp_path / "docs").exists()
    assert sorted(p.name for p in tuned.iterdir()) == ["apd-dc.toml", "comparison.md", "objective.png"]
    assert summary["tuning"]["apd-dc"]["preset"] == tuned / "apd-dc.toml"


def test_gains_file_errors_name_the_file_and_what_is_allowed(tmp_path):
    scenario = tmp_path / "s.toml"
    scenario.write_text(BASE.read_text().replace('gains = "default"', 'gains_file = "g.toml"'))
    with pytest.raises(ScenarioError, match="g.toml' does not exist"):
        load(scenario)
    (tmp_path / "g.toml").write_text("[gains]\nLambda_p = 1.0\n")
    with pytest.raises(ScenarioError, match="gains.Lambda_v is missing"):
        load(scenario)
    (tmp_path / "g.toml").write_text("[gains]\nLambda_p = 1.0\nLambda_v = 1.0\nb = 1.0\nD = 1.0\nK_T = 0.0\n")
    with pytest.raises(ScenarioError, match="K_T1 = 0.0 is invalid"):
        load(scenario)
    (tmp_path / "g.toml").write_text("[gains]\nLambda_p = 1.0\nLambda_v = [1.0, 2.0, 3.0]\nb = 1.0\nD = 1.0\nK_T = 1e-5\n")
    assert load(scenario).gain_values().Lambda_v == (1.0, 2.0, 3.0)
    assert math.isclose(load(scenario).gain_values().K_T[2], 1e-5)


def test_a_study_whose_cases_fail_exits_1_after_every_row_counting_each_status(faulty_ssps, tmp_path, capsys):
    # the plant FMU of this SSP fails its doStep from t = 0.5 ms on (tests/support/faults.py): every case fails
    path = write_study(tmp_path, '[set]\nstop_time = 0.002\n[grid]\nlaw = ["sc-dc", "apd-dc"]\n')
    code = main(["study", path, "--ssp", faulty_ssps["status"], "--workers", "1", "--no-progress"])
    out = capsys.readouterr().out.splitlines()
    assert code == 1
    assert out[-1].startswith("s: 2 cases (2 run now, ") and out[-1].endswith(
        f"s): 0 completed, 0 diverged, 2 failed -> {tmp_path / 'out' / 'study.csv'}")
    rows = rows_of(tmp_path / "out")
    assert [r["status"] for r in rows.values()] == ["failed", "failed"]
    assert all(r["error"] == "CoSimulationError: plant: doStep failed at t = 0.0005 s: a call returned ERROR, "
               "above fmi2Warning" for r in rows.values()), rows


def test_a_study_setting_outside_its_range_is_refused_before_any_case(built, tmp_path, capsys):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n"gain_overrides.D" = 2e9\n'
                       '[grid]\nlaw = ["sc-dc", "apd-dc"]\n')
    code = main(["study", path, "--ssp", built["ssp"], "--workers", "1", "--no-progress"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1 and "D1 = 2000000000.0 is invalid: allowed is a number in [0, 1e+09]" in err[0]
    assert not (tmp_path / "out" / "study.csv").exists()


@pytest.mark.parametrize("damage", ["[]", '{"name": "s"}', '{"fingerprint": "ab', "\x00\xff"])
def test_resume_with_a_damaged_study_json_is_one_line(built, tmp_path, capsys, damage):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n')
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "study.json").write_bytes(damage.encode("latin-1"))
    code = main(["study", path, "--ssp", built["ssp"], "--workers", "1", "--resume", "--no-progress"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err[-1].startswith(f"error: --resume: {tmp_path / 'out' / 'study.json'} is damaged (")
    assert err[-1].endswith("): the study cannot be matched with it; pass --overwrite to start again")
    assert not (tmp_path / "out" / "study.csv").exists()


def test_a_batch_dask_gives_up_is_a_failed_row_per_case_at_once(client):
    """A cancelled future (Dask gave the task up, e.g. with its worker) comes back from
    as_completed at once, never waited for: its result would not come; each case of its batch
    is a failed row saying so. A task that erred (KilledWorker) names its error in every row."""
    import time

    from dask.distributed import as_completed

    from orchestrator.studies.study import rows_of_batch
    fut = client.submit(time.sleep, 30, pure=False)
    fut.cancel()
    ((_, result),) = list(as_completed([fut], with_results=True, raise_errors=False))
    assert rows_of_batch([{"case": "c0000"}, {"case": "c0001"}], result) == [
        {"status": "failed", "error": "cancelled by Dask (its worker and its result were lost)"}] * 2
    erred = client.submit(math.sqrt, -1.0, pure=False)
    ((_, result),) = list(as_completed([erred], with_results=True, raise_errors=False))
    assert rows_of_batch([{"case": "c0000"}], result) == [{"status": "failed", "error": "ValueError: math domain error"}]


def test_resume_without_study_json_refuses_and_leaves_the_other_studys_rows(built, tmp_path, capsys):
    """Study A completes, its study.json is removed: study B with --resume cannot prove the rows
    are its own, so it refuses in one line and study.csv stays byte for byte."""
    a = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\n"gain_overrides.D" = [225.0, 450.0]\n', "a")
    assert main(["study", a, "--ssp", built["ssp"], "--workers", "1", "--no-progress"]) == 0
    (tmp_path / "out" / "study.json").unlink()
    before = (tmp_path / "out" / "study.csv").read_bytes()
    capsys.readouterr()
    b = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\n"gain_overrides.D" = [900.0, 1800.0]\n', "b")
    code = main(["study", b, "--ssp", built["ssp"], "--workers", "1", "--resume", "--no-progress"])
    out = capsys.readouterr()
    assert code == 2 and out.out == "" and out.err.splitlines()[-1] == (
        f"error: --resume: {tmp_path / 'out'} has no study.json, so nothing shows that its rows are this study's: "
        "run without --resume to start the study (--overwrite replaces a study.csv there)")
    assert (tmp_path / "out" / "study.csv").read_bytes() == before
    assert not (tmp_path / "out" / "study.json").exists()


def test_retry_failed_reruns_only_the_failed_rows_and_replaces_them(built, faulty_ssps, tmp_path, capsys):
    # the faulty plant fails its doStep from t = 0.5 ms on: the 0.3 ms case completes, the 2 ms one fails
    path = write_study(tmp_path, '[grid]\nstop_time = [0.0003, 0.002]\n')
    args = ["study", path, "--workers", "1", "--no-progress"]
    assert main([*args, "--ssp", faulty_ssps["status"]]) == 1
    table = tmp_path / "out" / "study.csv"
    header, completed, failed = table.read_bytes().splitlines(keepends=True)
    assert b",completed," in completed and b",failed," in failed
    assert main([*args, "--ssp", faulty_ssps["status"], "--resume"]) == 1  # --resume alone: failed rows stay
    assert table.read_bytes() == header + completed + failed
    capsys.readouterr()
    assert main([*args, "--ssp", built["ssp"], "--resume", "--retry-failed"]) == 0
    assert capsys.readouterr().out.splitlines()[-1].startswith("s: 2 cases (1 run now, ")
    lines = table.read_bytes().splitlines(keepends=True)
    assert lines[:2] == [header, completed] and len(lines) == 3
    assert rows_of(tmp_path / "out")["c0001"]["status"] == "completed"


def test_retry_failed_without_resume_is_refused(built, tmp_path, capsys):
    path = write_study(tmp_path, '[set]\nstop_time = 0.02\n[grid]\nlaw = ["sc-dc"]\n')
    code = main(["study", path, "--ssp", built["ssp"], "--workers", "1", "--retry-failed"])
    assert code == 2 and capsys.readouterr().err.splitlines() == [
        "error: --retry-failed goes with --resume, for a grid or Monte Carlo study: it runs the cases whose row in "
        "study.csv says failed again"]
    assert not (tmp_path / "out").exists()


def test_study_csv_is_never_appended_through_a_link_and_its_target_stays(tmp_path):
    from orchestrator.studies.study import StudyTable
    from orchestrator.tool.folders import LinkInTheWayError
    target = tmp_path / "elsewhere.txt"
    target.write_text("a user's file\n")
    (tmp_path / "out").mkdir()
    link = tmp_path / "out" / "study.csv"
    link.symlink_to(target)
    with pytest.raises(LinkInTheWayError, match="study.csv is a symbolic link"):
        StudyTable(link, ["D"])
    assert target.read_text() == "a user's file\n"
