"""The FMUs and their systems: `tapmp build` (every FMU family, or the FMI Cross-Check tree) and
`tapmp export` (a scenario as an SSP with its parameter set)."""

from pathlib import Path

from ctoolchain import PLATFORMS

from ..builder.families import ENV as FMUS_DIR_ENV, default_build_dir
from ..errors import UsageError
from .common import scenario_file, ssp_of
from .options import source_args

PLATFORM_NAMES = tuple(PLATFORMS)
# What --all-platforms costs (docs/native-fmus.md#build-time)
ALL_PLATFORMS_TIME = ("4 to 13 min the first time on a machine (Zig builds each target's C runtime once, the two "
                      "Windows ones longest), seconds afterwards")


def add_build(sub) -> None:
    """`tapmp build`."""
    b = sub.add_parser("build", help="build every FMU family and its SSP",
                       description="Build the pythonfmu family (TAPMP_Plant.fmu, TAPMP_Controller.fmu, "
                       "TAPMP_Trajectory.fmu, TAPMP.ssp and the closed-loop container FMU TAPMP_ClosedLoop.fmu) "
                       "into OUT and the native FMI 2.0 and 3.0 families into OUT/native/fmi2 and OUT/native/fmi3, "
                       "with this machine's binaries and their C sources (--all-platforms: Linux, Windows and macOS on x86-64 "
                       "and ARM), compiled by zig cc from the ziglang package ($CC for x86_64-linux if set). No "
                       "system compiler needed.")
    b.add_argument("--out", help=f"output folder (default: ${FMUS_DIR_ENV}, else the repository's build/ in a "
                   "checkout, else ./build)")
    b.add_argument("--platform", action="append", metavar="P",
                   help="build the native FMUs' binaries for these platforms only (repeatable): "
                   f"{', '.join(PLATFORM_NAMES)} (default: this machine's)")
    b.add_argument("--all-platforms", action="store_true",
                   help="binaries for every platform (the FMUs to hand to other machines): 4 to 13 min the first "
                   "time on a machine, seconds afterwards")
    b.add_argument("--cross-check", action="store_true",
                   help="instead of the families, write the native FMI 2.0 FMUs in the FMI Cross-Check layout into "
                   "OUT (default: ./cross-check): fmus/2.0/cs/<platform>/tapmp/<version>/<model>/ with the FMU, its "
                   "reference experiment (_ref.csv, _in.csv, _ref.opt) and ReadMe.txt; nothing else is built")
    b.add_argument("--clean-cache", action="store_true", help="first remove from the compiled-code cache "
                   "($TAPMP_CACHE, else ~/.cache/tapmp) the libraries and lock files older than this package's C "
                   "sources (left by earlier versions, checkouts and environments; rebuilt when used again)")
    b.set_defaults(func=cmd_build)


def cmd_build(args) -> int:
    """`tapmp build`: every FMU family and its SSP (or, with --cross-check, the Cross-Check tree)."""
    from ..builder.build import build_all
    from ..builder.build_native import build_native
    out = Path(args.out or default_build_dir())
    for p in args.platform or ():  # before building anything
        if p not in PLATFORMS:
            raise UsageError(f"--platform = {p!r} is invalid: allowed are {', '.join(PLATFORMS)}")
    if args.clean_cache:
        from ctoolchain import cache_dir, clean_cache
        removed = clean_cache(cache_sources())
        print(f"removed {len(removed)} stale file(s) from the compiled-code cache {cache_dir()}", flush=True)

    def log(line):
        print(line, flush=True)  # progress, also when the output is a pipe
    built = build_platforms(args)
    if set(built) == set(PLATFORMS):
        print(f"building every platform: {ALL_PLATFORMS_TIME}", flush=True)
    if args.cross_check:
        return build_cross_check(Path(args.out or "cross-check"), built, log)
    build_all(out, log)
    build_native(out / "native", platforms=built, log=log)
    from ..engine import stepper
    if stepper.available():  # else a note says why; runs then step in Python
        print(f"compiled stepping core in {stepper.build()}")  # the shipped one in a binary wheel
    if set(built) != set(PLATFORMS):
        print(f"the native FMUs hold binaries for {', '.join(p for p in PLATFORMS if p in built)} only (and their "
              f"C sources); `tapmp build --all-platforms` adds {', '.join(p for p in PLATFORMS if p not in built)} "
              f"({ALL_PLATFORMS_TIME})")
    return 0


def build_cross_check(out: Path, platforms, log) -> int:
    """`tapmp build --cross-check`: the native FMI 2.0 FMUs (built in a temporary folder, for ``platforms``)
    in the FMI Cross-Check layout under ``out``, and nothing else."""
    import tempfile
    from ..builder.build_native import build_native
    from ..builder.fmu_extras import cross_check_tree
    from tapmp.interface import FMU_NAMES
    with tempfile.TemporaryDirectory(prefix="tapmp_cross_check_") as tmp:
        native = build_native(Path(tmp), families=("fmi2",), platforms=platforms, log=log)
        fmus = {m: native["fmi2"][m] for m in FMU_NAMES}  # the default system's FMUs
        for folder in cross_check_tree(fmus, out):
            print(f"wrote {folder}", flush=True)
    return 0


def build_platforms(args) -> tuple[str, ...]:
    """The platforms `tapmp build` compiles the native FMUs for: --platform's, every one with
    --all-platforms, else this machine's alone (as `bash build_fmus.sh --host`, the quick start)."""
    from ctoolchain import HOST
    if args.platform:
        return tuple(args.platform)
    return tuple(PLATFORMS) if args.all_platforms else (HOST,)


def cache_sources() -> list[Path]:
    """The C sources of the libraries tapmp compiles into its cache (the C model, the stepping core)."""
    from tapmp import cmodel
    from ..engine import stepper
    return [cmodel.SOURCE, cmodel.HEADER, stepper.SOURCE]


def add_export(sub) -> None:
    """`tapmp export`."""
    ex = sub.add_parser("export", help="write a scenario as an SSP with its parameter set",
                        description="Write the SSP of the FMU family with the scenario's parameter set (SSP "
                        "ParameterValues, resources/<element>.ssv, bound to every element; the plant's initial "
                        "state included) and its start time, stop time and step in the DefaultExperiment, so that "
                        "libcosim, Ecos or FMPy run the scenario; and FILE.start-values.txt, the same values as "
                        "--start-values for `fmpy simulate` on TAPMP_ClosedLoop.fmu (also printed). Relative "
                        "paths are relative to the current directory; the SSP of --fmus is found in --fmus-dir.")
    source_args(ex)
    ex.add_argument("--out", required=True, help="SSP file to write, ending in .ssp, e.g. export/paper.ssp")
    ex.add_argument("--overwrite", action="store_true", help="replace an existing FILE.ssp and its start values")
    ex.set_defaults(func=cmd_export)


def cmd_export(args) -> int:
    """`tapmp export`: the scenario's SSP with its parameter set, and the container's start values."""
    from ..tool.export import export
    from ..tool.scenario import load
    scenario = load(scenario_file(args.scenario), args.set)
    source = ssp_of(args, scenario)
    ssp, values = export(scenario, source, Path(args.out), args.overwrite)
    pairs = values.read_text().split()
    print(f"wrote {ssp} (SSP 1.0: the FMUs of {source}, parameter set "
          f"{scenario.name!r} bound to every element, {scenario.n_steps} steps of {scenario.step:g} s to "
          f"{scenario.stop_time:g} s)")
    print(f"wrote {values} (--start-values for fmpy simulate on TAPMP_ClosedLoop.fmu):")
    print(" ".join(pairs))
    return 0
