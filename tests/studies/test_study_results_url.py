"""--results-url: the workers write each case's files to a location the user names, through a
real FTP server (pyftpdlib, on loopback in this process) as an fsspec URL, and to a plain path; on
a real two-worker Dask LocalCluster through the native FMUs. The files equal those of the same
study run into its output folder; nothing but study.csv, study.json and the figures lands there."""

import json
import threading
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.studies.run import run_study
from orchestrator.studies.study import StudyError, load_study
from tests.support.studies import client, write_study  # noqa: F401 (client is a fixture)

KEPT = '[set]\nstop_time = 0.02\n[grid]\n"gain_overrides.D" = [450.0, 900.0, 1800.0]\n'


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    """The native FMI 2.0 FMUs for this machine and their SSP."""
    from orchestrator.builder.build_native import build_native
    return build_native(tmp_path_factory.mktemp("native"), families=("fmi2",), log=lambda *_: None,
                        windows=False)["fmi2"]["ssp"]


@pytest.fixture
def ftp(tmp_path):
    """An FTP server on a free loopback port whose user "tapmp" (password "secret") owns
    ``tmp_path``/ftp; yields (its URL, that folder)."""
    import warnings
    with warnings.catch_warnings():  # pyftpdlib is built on asyncore, deprecated in Python 3.11
        warnings.simplefilter("ignore", DeprecationWarning)
        from pyftpdlib.authorizers import DummyAuthorizer
        from pyftpdlib.handlers import FTPHandler
        from pyftpdlib.servers import FTPServer
    home = tmp_path / "ftp"
    home.mkdir()
    authorizer = DummyAuthorizer()
    authorizer.add_user("tapmp", "secret", str(home), perm="elradfmw")  # list, read, write, rename, mkdir, delete
    handler = type("Handler", (FTPHandler,), {"authorizer": authorizer})
    server = FTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, kwargs={"timeout": 0.1}, daemon=True)
    thread.start()
    yield f"ftp://tapmp:secret@127.0.0.1:{server.address[1]}", home
    server.close_all()
    thread.join(timeout=10)


def files_of(folder: Path) -> dict:
    """{case/file: content} under ``folder``, run.json without its wall times."""
    out = {}
    for path in sorted(folder.glob("*/*")):
        if path.name == ".tapmp.lock":
            continue
        data = path.read_text()
        if path.name == "run.json":
            data = {k: v for k, v in json.loads(data).items() if k not in ("wall_time_s", "real_time_factor")}
        out[f"{path.parent.name}/{path.name}"] = data
    return out


@pytest.mark.slow  # studies on the LocalCluster and an FTP server
def test_kept_results_go_to_an_ftp_server_and_equal_a_study_into_its_folder(ssp, client, ftp, tmp_path):
    url, home = ftp
    study = load_study(write_study(tmp_path, "keep_results = true\n" + KEPT))
    run_study(study, ssp, client, tmp_path / "here", progress=False)
    summary = run_study(study, ssp, client, tmp_path / "there", progress=False, results_url=f"{url}/kept")
    assert summary["counts"]["completed"] == 3
    sent = files_of(home / "kept")
    assert sent == files_of(tmp_path / "here" / "cases")
    assert {name.split("/")[1] for name in sent} == {"run.json", "metrics.json", "results.csv"}
    assert not list(home.rglob("*.tmp")) and not (tmp_path / "there" / "cases").exists()
    assert (tmp_path / "there" / "study.csv").read_text().count("completed") == 3


@pytest.mark.slow  # a study on the LocalCluster
def test_a_plain_path_every_worker_sees_takes_the_files_too(ssp, client, tmp_path):
    study = load_study(write_study(tmp_path, KEPT))
    run_study(study, ssp, client, tmp_path / "here", progress=False)
    run_study(study, ssp, client, tmp_path / "there", progress=False, results_url=str(tmp_path / "shared"))
    assert files_of(tmp_path / "shared") == files_of(tmp_path / "here" / "cases") != {}


def test_a_location_that_refuses_writing_is_one_line_before_any_case(ftp, tmp_path, capsys):
    url, home = ftp
    study = write_study(tmp_path, KEPT)
    code = main(["study", str(study), "--results-url", url.replace("secret", "wrong") + "/x"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err[-1].startswith(f"error: --results-url {url.replace('secret', '***')}/x: cannot write "
                                            "there (")
    assert "wrong" not in err[-1] and not (tmp_path / "out").exists()


@pytest.mark.parametrize("url, message", [
    ("relative/folder", "--results-url = 'relative/folder' is invalid: allowed is an absolute path every worker sees"),
    ("nosuch://host/x", "--results-url = 'nosuch://host/x' is invalid: Protocol not known: nosuch; allowed is "),
])
def test_a_relative_path_or_an_unknown_protocol_is_refused(tmp_path, capsys, url, message):
    assert main(["study", str(write_study(tmp_path, KEPT)), "--results-url", url]) == 2
    assert capsys.readouterr().err.splitlines()[-1].startswith(f"error: {message}")


def test_a_tuning_is_refused_with_results_url(tmp_path):
    study = load_study(write_study(tmp_path, '[set]\nstop_time = 0.01\n[tune]\nlaws = ["apd-dc"]\npopulation = 2\n'
                                  'generations = 1\nseed = 1\nwrite_to = "unused"\n[tune.bounds.apd-dc]\n'
                                  'Lambda_v = [0.2, 2.0]\n'))
    (tmp_path / "x.ssp").write_bytes(b"not read: refused before")
    with pytest.raises(StudyError, match="^--results-url is for a grid or Monte Carlo study"):
        run_study(study, tmp_path / "x.ssp", None, tmp_path / "o", results_url=str(tmp_path / "r"))
    assert not (tmp_path / "r").exists() and not (tmp_path / "o").exists()
