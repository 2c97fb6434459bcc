"""`tapmp build`'s platforms: this machine's by default, wherever it runs (in a checkout or not), as the quick
start's `bash build_fmus.sh --host`; every platform only when asked (--all-platforms), the time stated."""

import subprocess
import sys
import zipfile

import pytest

from tests.support.shared import ROOT

pytestmark = pytest.mark.slow  # builds every family for this machine


def test_tapmp_build_outside_a_checkout_builds_the_hosts_platform_only(tmp_path):
    """Run from a folder that is no checkout, into ./fmus: every native FMU holds x86_64-linux binaries and
    nothing else, and the command says how to add the others and what that costs."""
    work = tmp_path / "elsewhere"
    work.mkdir()
    done = subprocess.run([sys.executable, "-m", "orchestrator", "build", "--out", "fmus"], cwd=work,
                          capture_output=True, text=True, timeout=1200,
                          env={"PATH": "/usr/bin:/bin", "HOME": str(tmp_path), "PYTHONPATH": str(ROOT),
                               "TMPDIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr
    assert "native: compiling 9 FMUs (fmi2, fmi3) for 1 platform(s): x86_64-linux" in done.stdout  # the drive's two
    fmus = sorted((work / "fmus" / "native").glob("fmi*/*.fmu"))
    assert len(fmus) == 9
    for fmu in fmus:
        with zipfile.ZipFile(fmu) as z:
            folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}
        assert folders == ({"linux64"} if fmu.parent.name == "fmi2" else {"x86_64-linux"}), fmu
    last = done.stdout.strip().splitlines()[-1]
    assert last.startswith("the native FMUs hold binaries for x86_64-linux only (and their C sources); "
                           "`tapmp build --all-platforms` adds aarch64-linux, x86_64-windows, x86-windows, "
                           "x86_64-darwin, aarch64-darwin (4 to 13 min the first time on a machine")


def test_tapmp_build_help_names_the_default_and_the_option_for_every_platform():
    from orchestrator.cli import parser
    text = " ".join(parser()._subparsers._group_actions[0].choices["build"].format_help().split())
    assert "(default: this machine's)" in text
    assert "--all-platforms binaries for every platform (the FMUs to hand to other machines): 4 to 13 min" in text
