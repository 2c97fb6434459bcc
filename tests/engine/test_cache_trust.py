"""The compiled-code cache ($TAPMP_CACHE, else under $XDG_CACHE_HOME or $HOME) is trusted as ssh
trusts its keys: the folder, every folder above it and every library loaded from it must belong to
the user running tapmp and be writable by no one else. A library another user could have planted
is never loaded: `tapmp run` stops with one line naming the path and what is wrong, exit 2, and
the planted library's constructor never runs (it would write a marker file).

CI runs as root: "another user" is nobody (chown)."""

import os
import pwd
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from orchestrator.engine import stepper
from tapmp import cmodel
from ctoolchain import compile_c

pytestmark = pytest.mark.slow  # child processes, a C compile

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
NOBODY = 65534
PLANT = r"""
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>
__attribute__((constructor)) static void planted(void)
{
    FILE *f = fopen(getenv("PLANT_MARKER"), "w");
    if (f) { fprintf(f, "planted library ran as uid %d\n", (int)getuid()); fclose(f); }
}
"""


@pytest.fixture(scope="module")
def planted_library(tmp_path_factory):
    """A shared library whose constructor writes the file $PLANT_MARKER."""
    folder = tmp_path_factory.mktemp("plant")
    (folder / "plant.c").write_text(PLANT)
    return compile_c([folder / "plant.c"], folder / "plant.so")


def names(cache: Path) -> dict:
    """{"model" | "stepper": the path in ``cache`` each library is loaded from}."""
    env = {**os.environ, "TAPMP_CACHE": str(cache)}
    code = ("from tapmp import cmodel; from orchestrator.engine import stepper; "
            "print(cmodel.cached_library_path()); print(stepper.library_path())")
    model, core = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                 check=True).stdout.split()
    return {"model": Path(model), "stepper": Path(core)}


def tapmp_run(built, tmp_path, cache: Path):
    """`tapmp run` of a short scenario with the cache ``cache``; (exit code, stderr lines, marker)."""
    marker = tmp_path / "marker"
    env = {**os.environ, "TAPMP_CACHE": str(cache), "PLANT_MARKER": str(marker)}
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(built["ssp"]),
                          "--out", str(tmp_path / "out"), "--set", "stop_time=0.002", "--no-progress"],
                         env=env, capture_output=True, text=True, timeout=300)
    return res.returncode, res.stderr.splitlines(), marker


def own_libraries(cache: Path) -> dict:
    """The cache folder ``cache`` (mode 0700) with the real model and stepping-core libraries of
    this user, copied from the default cache; returns their paths."""
    cache.mkdir(mode=0o700)
    paths = names(cache)
    shutil.copyfile(cmodel.library_path(), paths["model"])
    shutil.copyfile(stepper.build(), paths["stepper"])
    for p in paths.values():
        p.chmod(0o755)
    return paths


@pytest.mark.parametrize("library", ["model", "stepper"])
def test_a_library_owned_by_another_user_is_refused_and_never_runs(built, tmp_path, planted_library, library):
    cache = tmp_path / "cache"
    paths = own_libraries(cache)
    shutil.copyfile(planted_library, paths[library])
    os.chown(paths[library], NOBODY, -1)
    code, err, marker = tapmp_run(built, tmp_path, cache)
    assert code == 2 and not marker.exists()
    assert err == [f"error: the compiled-code cache: {paths[library]} belongs to uid {NOBODY} (nobody), not to "
                   f"this user (uid {os.geteuid()} ({pwd.getpwuid(os.geteuid()).pw_name})), so it may be a library another user planted; tapmp does "
                   "not load it: delete it, or set TAPMP_CACHE to a folder of your own that only you can write "
                   "(chmod 700)"]
    assert not (tmp_path / "out" / "results.csv").exists()


@pytest.mark.parametrize("mode, who", [(0o770, "its group"), (0o777, "its group and others"), (0o702, "others")])
def test_a_cache_folder_others_may_write_is_refused_and_nothing_in_it_runs(built, tmp_path, planted_library,
                                                                         mode, who):
    cache = tmp_path / "cache"
    paths = own_libraries(cache)
    for p in paths.values():  # files of this user, but anyone could have put them there
        shutil.copyfile(planted_library, p)
    cache.chmod(mode)
    code, err, marker = tapmp_run(built, tmp_path, cache)
    assert code == 2 and not marker.exists()
    assert err == [f"error: the compiled-code cache: {cache} is writable by {who} (mode {mode:04o}), so another "
                   "user could plant a library there that tapmp would run: set TAPMP_CACHE to a folder of your own "
                   "that only you can write (chmod 700)"]


def test_a_cache_under_a_folder_others_may_write_is_refused(built, tmp_path, planted_library):
    """Whoever may write the folder above could rename the cache away and put their own in its place."""
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)  # no sticky bit, unlike /tmp
    cache = shared / "cache"
    for p in own_libraries(cache).values():
        shutil.copyfile(planted_library, p)
    code, err, marker = tapmp_run(built, tmp_path, cache)
    assert code == 2 and not marker.exists()
    assert err == [f"error: a folder above the compiled-code cache {cache}: {shared} is writable by its group and "
                   "others (mode 0777), so another user could plant a library there that tapmp would run: set "
                   "TAPMP_CACHE to a folder of your own that only you can write (chmod 700)"]


def test_a_symbolic_link_in_the_cache_is_refused(built, tmp_path, planted_library):
    cache = tmp_path / "cache"
    paths = own_libraries(cache)
    paths["model"].unlink()
    paths["model"].symlink_to(planted_library)
    code, err, marker = tapmp_run(built, tmp_path, cache)
    assert code == 2 and not marker.exists()
    assert err == [f"error: the compiled-code cache: {paths['model']} is not a regular file (a symbolic link or "
                   "other), so it could lead to a library another user planted: delete it, or set TAPMP_CACHE to a "
                   "folder of your own that only you can write (chmod 700)"]


def test_a_library_of_this_user_that_cannot_be_loaded_is_one_line(built, tmp_path, planted_library):
    """The user's own file, but not the C model (an interrupted copy, a stale file): one line naming
    it and the missing function, no AttributeError traceback."""
    cache = tmp_path / "cache"
    paths = own_libraries(cache)
    shutil.copyfile(planted_library, paths["model"])
    code, err, _ = tapmp_run(built, tmp_path, cache)
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"error: cannot load the compiled C model {paths['model']}: function/symbol ")
    assert err[0].endswith("(delete the file so that it is compiled again)")


def test_a_new_cache_folder_is_private_and_a_run_completes(built, tmp_path):
    cache = tmp_path / "new" / "cache"
    code, err, _ = tapmp_run(built, tmp_path, cache)
    assert code == 0, err
    assert cache.stat().st_mode & 0o777 == 0o700
    assert (tmp_path / "out" / "results.csv").is_file()
