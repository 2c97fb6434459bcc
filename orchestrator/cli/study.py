"""Parameter studies on Dask: `tapmp study` (a grid, Monte Carlo or tuning study file)."""

from pathlib import Path

from .common import check_workers, record_every, shipped_names, ssp_of, study_file
from .options import fmu_args, progress_arg, recording_args


def add_study(sub) -> None:
    """`tapmp study`."""
    st = sub.add_parser("study", help="run a parameter study on Dask",
                        description="Run every case of a study file (grid, Monte Carlo or tuning) as an "
                        "independent co-simulation on Dask workers; one row per case in OUTPUT/study.csv.")
    st.add_argument("study", help="study TOML file, e.g. studies/robustness.toml, or the name of a study "
                    f"shipped with the package: {', '.join(shipped_names('studies'))}")
    st.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 "
                    "(default: a LocalCluster on this machine)")
    st.add_argument("--workers", type=int, help="worker processes of the LocalCluster (default: one per core)")
    st.add_argument("--shared-fs", action="store_true", help="with --scheduler: the workers see this machine's "
                    "files at the same paths (a shared file system); they read the SSP and write the case folders "
                    "themselves instead of receiving the SSP and sending each case's files back")
    st.add_argument("--worker-timeout", type=float, default=60.0, metavar="S", help="how long to wait for the "
                    "scheduler and for its first worker [s] (default 60)")
    st.add_argument("--max-cases", type=int, metavar="N", help="run a study of more than 100000 cases (up to N)")
    st.add_argument("--out", help="output folder (overrides the study's 'output')")
    st.add_argument("--batch-size", type=int, default=0, metavar="N", help="cases per Dask task (default 0: "
                    "about 1 s of work per task from the cases' steps, at least 4 tasks per worker, at most 200)")
    st.add_argument("--results-url", metavar="PATH|URL", help="the workers write each case's files to "
                    "PATH|URL/CASE/ themselves (an absolute path every worker sees, or an fsspec URL such as "
                    "ftp://USER:PASSWORD@HOST/FOLDER) instead of sending them back; study.csv stays in --out")
    fmu_args(st)
    st.add_argument("--resume", action="store_true", help="run only the cases without a row in study.csv")
    st.add_argument("--retry-failed", action="store_true", help="with --resume: run the cases whose row says "
                    "failed again, replacing their rows")
    st.add_argument("--overwrite", action="store_true", help="start again in an output folder with a study.csv")
    recording_args(st)
    st.add_argument("--write-docs", action="store_true", help="a tuning study: write its presets, comparison.md "
                    "and objective.png into its [tune] write_to folder (studies/tune.toml: docs/tuning) instead "
                    "of OUT/tuning")
    progress_arg(st)
    st.set_defaults(func=cmd_study)


def cmd_study(args) -> int:
    """`tapmp study`: 0 if every case ran (completed, diverged or rejected), 1 if any failed (an error)."""
    from ..studies.run import run_study
    from ..engine.tempdirs import remove_stale_folders
    from ..tool.estimate import check_output_size
    from ..tool.folders import output_lock
    from ..tool.progress import say
    from ..studies.study import MAX_CASES, StudyError, check_case_count, close_client, load_study, open_client
    study = load_study(study_file(args.study))
    every = record_every(args.record_every) if args.record_every is not None else None
    if args.write_docs and not study.tune:
        raise StudyError(f"--write-docs: {args.study} has no [tune] table; only a tuning writes a write_to folder")
    if args.workers is not None:
        check_workers(args.workers)
    if args.scheduler and args.workers is not None:
        raise StudyError("--workers is for the local cluster: with --scheduler the cluster's own workers run the cases")
    if args.shared_fs and not args.scheduler:
        raise StudyError("--shared-fs is for a cluster given by --scheduler (the local cluster shares this disk)")
    max_cases = MAX_CASES if args.max_cases is None else args.max_cases
    if max_cases < 1:
        raise StudyError(f"--max-cases = {max_cases} is invalid: allowed is an integer >= 1")
    if args.retry_failed and not (args.resume and not study.tune):
        raise StudyError("--retry-failed goes with --resume, for a grid or Monte Carlo study: it runs the cases "
                         "whose row in study.csv says failed again")
    if args.batch_size < 0:
        raise StudyError(f"--batch-size = {args.batch_size} is invalid: allowed is an integer >= 1, or 0 for the "
                         "automatic size")
    if not args.worker_timeout > 0:
        raise StudyError(f"--worker-timeout = {args.worker_timeout:g} is invalid: allowed is a number > 0 [s]")
    if args.results_url:  # before a cluster starts (run_study checks it again for its other callers)
        if study.tune:
            raise StudyError("--results-url is for a grid or Monte Carlo study: a tuning reads its cases' files")
        from ..studies.publish import check_location
        check_location(args.results_url)
    if not study.tune:
        check_case_count(study, max_cases)  # before the cases are listed
    if args.format or args.record_every is not None:  # scenario keys, applied like the study's [set]
        import dataclasses
        recording = {k: v for k, v in (("format", args.format), ("record_every", every)) if v is not None}
        study = dataclasses.replace(study, set={**study.set, **recording})
    out = Path(args.out or study.output)
    case_list = None
    if not study.tune:
        from ..studies.study import cases
        case_list = cases(study, max_cases)  # every case validated before a cluster starts
    # kept results come into --out (else each case deletes its result file once scored, or --results-url holds them)
    if study.keep_results and not study.tune and not args.results_url:
        check_output_size([study.base_scenario()] * len(case_list), out, study.name, args.workers or 1)
    # after the cases (a study file's error first), before starting a cluster; the drive's SSP if the base has it
    ssp = ssp_of(args, drive=study.base_scenario().drive is not None)
    if not ssp.exists():
        raise StudyError(f"SSP file {ssp} does not exist: build the FMUs first (bash build_fmus.sh, "
                         "or tapmp build) or pass --ssp")
    reference = None
    if study.tune:  # the paper's rows beside a tuning of a paper scenario (None for any other)
        from ..paper.paper_tables import reference_rows
        reference = reference_rows(study.base_scenario().name)
    remote = None
    with output_lock(out):  # before starting a cluster; run_study takes it again (re-entrant)
        if args.scheduler:
            say(f"{study.name}: connecting to the Dask scheduler at {args.scheduler}")
            remote = {"address": args.scheduler, "data": not args.shared_fs, "timeout": args.worker_timeout}
        else:
            say(f"{study.name}: starting the Dask workers")
        client = open_client(args.scheduler, args.workers, args.worker_timeout)
        try:
            command = args.command_line
            say(f"{study.name}: running the cases -> {out}")
            s = run_study(study, ssp, client, out, args.resume, args.overwrite,
                          not args.no_progress, command, args.write_docs, remote, max_cases, case_list,
                          args.retry_failed, reference, args.batch_size, args.results_url or "")
        finally:
            close_client(client)
            remove_stale_folders()  # of local workers that were killed, not stopped
    for f in s["figures"]:
        print(f"wrote {f}")
    c = s["counts"]
    counts = (f"{c['completed']} completed, {c['diverged']} diverged, {c['failed']} failed"
              + (f", {c['rejected']} rejected (not stable, not run)" if c["rejected"] else "")
              + (f"; {s['unstable']} of them unstable by the stability check (flag in study.csv)"
                 if s.get("unstable") else ""))
    if study.tune:
        for law, r in s["tuning"].items():
            start = f"{r['start']:.4f} um" if r["start"] is not None else "not run (start gains rejected)"
            print(f"{law}: objective {start} (start gains) -> {r['tuned']:.4f} um (tuned, "
                  f"{r['evaluations']} evaluations); preset {r['preset']}")
        print(f"presets, comparison and objective plot in {s['write_to']}")
        print(f"{study.name}: {s['cases']} evaluations ({s['wall_time_s']:.1f} s): {counts} -> "
              f"{s['out'] / 'study.csv'}")
    else:
        print(f"{study.name}: {s['cases']} cases ({s['ran']} run now, {s['wall_time_s']:.1f} s): {counts} -> "
              f"{s['out'] / 'study.csv'}")
    return 1 if c["failed"] else 0

