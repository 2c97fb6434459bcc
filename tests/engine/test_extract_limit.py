"""What an SSP and the FMUs in it may write when extracted is bounded: at most 2 GiB uncompressed in
total by default ($TAPMP_EXTRACT_LIMIT raises or lowers it), checked against the declared sizes
before anything is written and against the bytes written while extracting. Over the limit: one line
naming the SSP, the FMU and the limit, exit 2, through the real `tapmp run`. (Before, a deflate bomb
nested in an FMU wrote about 1 GiB per MB of archive into the temporary folder.)"""

import os
import re
import struct
import subprocess
import sys
import zipfile
import zlib
from pathlib import Path

import pytest

from orchestrator.engine.archive import ExtractLimitError, extract_limit

pytestmark = pytest.mark.slow  # child processes

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "scenarios" / "paper_simulation.toml")
PLANT = "resources/TAPMP_Plant.fmu"
BOMB = "resources/bomb.bin"


def declare_size(path: Path, member: str, size: int) -> None:
    """Make the zip file ``path`` declare ``size`` bytes for ``member`` (local header and central directory)."""
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = z.getinfo(member)
    struct.pack_into("<I", data, info.header_offset + 22, size)
    name = member.encode()
    at = data.find(b"PK\x01\x02")
    while at >= 0:
        n = struct.unpack_from("<H", data, at + 28)[0]
        if data[at + 46:at + 46 + n] == name:
            struct.pack_into("<I", data, at + 24, size)
            path.write_bytes(bytes(data))
            return
        at = data.find(b"PK\x01\x02", at + 4)
    raise AssertionError(f"{member} not in the central directory of {path}")


def ssp_with_bomb(built, tmp_path: Path, content: bytes, declared: int | None) -> Path:
    """The built SSP whose plant FMU also holds BOMB (``content`` deflated, declaring ``declared`` bytes)."""
    fmu = tmp_path / "TAPMP_Plant.fmu"
    with zipfile.ZipFile(built["ssp"]) as ssp:
        fmu.write_bytes(ssp.read(PLANT))
        members = {i.filename: ssp.read(i) for i in ssp.infolist()}
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as z:
        z.writestr(BOMB, content)
    if declared is not None:
        declare_size(fmu, BOMB, declared)
    members[PLANT] = fmu.read_bytes()
    out = tmp_path / "bomb.ssp"
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return out


def tapmp_run(ssp, tmp_path, **env):
    res = subprocess.run([sys.executable, "-m", "orchestrator", "run", PAPER, "--ssp", str(ssp), "--out",
                          str(tmp_path / "out"), "--set", "stop_time=0.001", "--no-progress"],
                         capture_output=True, text=True, timeout=300, env={**os.environ, **env}, cwd=tmp_path)
    return res.returncode, res.stderr.splitlines()


def test_an_fmu_declaring_more_than_the_limit_is_refused_before_extraction(built, tmp_path):
    ssp = ssp_with_bomb(built, tmp_path, b"\0" * 16, 3 * 2**30)
    code, err = tapmp_run(ssp, tmp_path, TMPDIR=str(tmp_path))
    assert code == 2 and len(err) == 1
    # 3 GiB declared by the bomb plus the FMU's own members (printed to 4 digits: 3.001 GiB)
    assert re.match(re.escape(f"error: SSP file {ssp}: the FMU {PLANT} of element plant: extracting its members (")
                    + r"3(\.\d+)? GiB\) would write more than the limit", err[0]), err[0]
    assert err[0].endswith("would write more than the limit of 2 GiB uncompressed in total, with what was extracted "
                           "before: allowed is an archive within the limit; set TAPMP_EXTRACT_LIMIT (e.g. "
                           "TAPMP_EXTRACT_LIMIT=8GiB) to raise it")
    assert not list(tmp_path.glob("tapmp_cosim_*"))  # its temporary folder is gone


def test_a_deflate_bomb_over_a_lowered_limit_is_refused_and_a_raised_limit_runs(built, tmp_path):
    ssp = ssp_with_bomb(built, tmp_path, b"\0" * 2**25, None)  # 32 MiB of zeros: 32 KiB in the archive
    assert ssp.stat().st_size < 2**21
    code, err = tapmp_run(ssp, tmp_path, TAPMP_EXTRACT_LIMIT="16MiB")
    assert code == 2 and len(err) == 1
    assert f"extracting its members (" in err[0] and "would write more than the limit of 16 MiB" in err[0]
    code, err = tapmp_run(ssp, tmp_path, TAPMP_EXTRACT_LIMIT="64MiB")
    assert code == 0, err


def test_a_member_that_lies_about_its_size_is_one_line(built, tmp_path):
    """It declares 1 KiB but inflates to 32 MiB: extraction stops at the declared size (zipfile's
    own bound, counted against the limit too) and the run ends in one line."""
    ssp = ssp_with_bomb(built, tmp_path, b"\0" * 2**25, 1024)
    code, err = tapmp_run(ssp, tmp_path)
    assert code == 2 and len(err) == 1 and err[0].startswith(f"error: SSP file {ssp}: cannot load the FMU {PLANT}")


@pytest.mark.parametrize("text, limit", [("", 2 * 2**30), ("4096", 4096), ("8GiB", 8 * 2**30), ("1.5M", 3 * 2**19)])
def test_the_limit_is_read_from_the_environment(monkeypatch, text, limit):
    monkeypatch.setenv("TAPMP_EXTRACT_LIMIT", text)
    assert extract_limit() == limit


@pytest.mark.parametrize("text", ["0", "-1", "lots", "8 parsecs"])
def test_an_invalid_limit_is_refused_naming_it(monkeypatch, text):
    monkeypatch.setenv("TAPMP_EXTRACT_LIMIT", text)
    with pytest.raises(ExtractLimitError, match=rf"TAPMP_EXTRACT_LIMIT = '{text}' is invalid: allowed is a size"):
        extract_limit()
