"""The test session's own temporary folder (a pytest plugin, loaded by tests/conftest.py).

When pytest starts, the session makes one folder of its own in the system's temporary folder
(``tapmp-tests-XXXX``) and points ``TMPDIR`` and Python's ``tempfile`` at it, so everything the
suite writes to "the temporary folder" outside its fixtures (at import and collection, in child
processes) lands there and nowhere else. tests/project/test_temp_folder.py measures that folder
only: another process's files in /tmp (a concurrent job, pip's unpack folders) are not the suite's
and do not count. pytest's own base folder stays where pytest puts it (the system's temporary
folder, its last three sessions kept), measured apart.

The folder is removed when the session ends with no test failed, and kept after a failure (as
pytest keeps a failed session's base folder) for the post-mortem.
"""

import os
import shutil
import tempfile
from pathlib import Path


def pytest_configure(config):
    system = tempfile.gettempdir()
    config.system_temp = system
    # pytest's base folder is computed later from the temporary folder: it stays in the system's
    os.environ.setdefault("PYTEST_DEBUG_TEMPROOT", system)
    config.suite_temp = Path(tempfile.mkdtemp(prefix="tapmp-tests-", dir=system))
    config.suite_temp_restore = (os.environ.get("TMPDIR"), tempfile.tempdir)
    os.environ["TMPDIR"] = str(config.suite_temp)
    tempfile.tempdir = str(config.suite_temp)


def pytest_sessionfinish(session, exitstatus):
    config = session.config
    if getattr(config, "suite_temp", None) is not None and exitstatus == 0:
        shutil.rmtree(config.suite_temp, ignore_errors=True)


def pytest_unconfigure(config):
    if getattr(config, "suite_temp", None) is None:
        return
    env, tempdir = config.suite_temp_restore
    if env is None:
        os.environ.pop("TMPDIR", None)
    else:
        os.environ["TMPDIR"] = env
    tempfile.tempdir = tempdir
