"""Result file writers: rows appended in whole blocks to results.csv or (through
results.part.npy) results.mat.

results.csv is text, every value as the shortest text that reads back to it, formatted and
written by a thread of its own while the run steps on (the compiled stepping core releases the
GIL, so the text costs the run little wall time where a second core is free); results.mat
is a MATLAB 5 MAT-file with one N x 1 double variable per column (names with "." as "_")
plus ``columns``, the original names in order. A block is formatted in one operation (one
orjson call for CSV, raw float64 bytes for MAT) and written with one os.write. After a
failed write (e.g. a full disk) the file is cut back to its last whole block. A MAT run
streams its blocks into results.part.npy (a valid .npy file whose header is updated after
every whole block) and writes results.mat from it atomically when the run ends for any
reason Python sees; only a killed process (SIGKILL, power loss) leaves results.part.npy,
which reading.read_results reads as well.
"""

import hashlib
import io
import os
import queue
import re
import threading
from pathlib import Path

import numpy as np
import orjson
from numpy.lib import format as npy

from .folders import FORMATS, PART_FILE, ResultsWriteError, atomic_file, new_stream


def _write_error(path: Path, err: OSError, detail: str = "") -> ResultsWriteError:
    return ResultsWriteError(f"cannot write {path}: {err.strerror or err} (errno {err.errno}){detail}")


class _Blocks:
    """A result file written in whole blocks of rows (one os.write per block); after a
    failed write (e.g. a full disk) the file is cut back to the end of its last whole block."""

    def __init__(self, path: Path, columns):
        self.path = Path(path)
        self.columns = list(columns)
        try:
            self.fd = new_stream(self.path)  # a new file renamed into place: never opened through a link
        except OSError as err:
            raise _write_error(self.path, err) from err
        self.size = 0            # bytes of whole blocks on disk
        self._sha256 = hashlib.sha256()  # of those bytes, computed as they are written (folders.file_record)
        self.rows = 0            # rows on disk
        self.last_time = None    # time [s] of the last row on disk

    def _append(self, data: bytes, rows: int, last_time, quiet: bool) -> bool:
        """Append one block of bytes; on failure cut back to whole blocks and raise
        ResultsWriteError (or return False if ``quiet``)."""
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(self.fd, view):]
        except OSError as err:
            try:
                os.ftruncate(self.fd, self.size)  # whole rows only
            except OSError:
                self._sha256 = None  # the file may hold more than the hashed blocks
            if quiet:
                return False
            kept = (f"the rows up to t = {self.last_time:.6g} s" if self.last_time is not None
                    else "no rows")
            raise _write_error(self.path, err, f": it keeps {kept}, whole rows only") from err
        self.size += len(data)
        if self._sha256 is not None:
            self._sha256.update(data)  # in the writing thread of a CSV run: off the stepping thread
        self.rows += rows
        if last_time is not None:
            self.last_time = last_time
        return True

    def record(self) -> dict | None:
        """The file's folders.file_record as written ({"size", "sha256"}), None if not known; valid once
        finish() has returned."""
        return None if self._sha256 is None else {"size": self.size, "sha256": self._sha256.hexdigest()}

    def close(self) -> None:
        os.close(self.fd)


class CsvBlocks(_Blocks):
    """results.csv: a header of column names, then one line per row, every value as the
    shortest decimal text that reads back to the same double (the digits of Python's repr;
    small and large magnitudes in plain or exponent notation, e.g. 0.00001, -2.5e-7,
    1e+16). A block is formatted in one call to orjson's numpy serializer (compiled,
    about 20x faster than Python's %-formatting of every value) and its JSON rows turned
    into lines; a block holding a non-finite value (never written by the master, which
    stops before) is formatted with Python's repr.

    Formatting and writing run in a thread of their own, started at the first block: write()
    hands a copy of the block over (at most QUEUED blocks wait, so memory stays bounded) and
    returns while the run steps on. A write that fails (a full disk) cuts the file back to its
    whole blocks as before; its ResultsWriteError is raised by the next write() or by finish(),
    and nothing after it is written. finish() waits until every block is on disk."""

    QUEUED = 4  # blocks waiting for the writing thread: bounded memory, and enough to ride out a slow write

    def __init__(self, out: Path, columns):
        super().__init__(Path(out) / FORMATS["csv"], columns)
        self.header = (",".join(self.columns) + "\n").encode()
        self.line = ",".join(["%r"] * len(self.columns)) + "\n"
        self._queue = queue.Queue(self.QUEUED)
        self._thread = None
        self._error = None  # the first failure of the writing thread, raised in the caller's thread

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        """Hand the rows of ``block`` (n x columns) to the writing thread (the header goes with the
        first block); raises the ResultsWriteError of an earlier block that failed (unless ``quiet``)."""
        self._raise(quiet)
        if not block.shape[0] or self._error is not None:
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"write {self.path}", daemon=True)
            self._thread.start()
        self._queue.put((np.array(block, dtype=np.float64), quiet))  # a copy: the caller reuses its buffer

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                block, quiet = item
                if self._error is None:
                    data = (self.header if self.size == 0 else b"") + format_csv_rows(block, self.line)
                    self._append(data, block.shape[0], float(block[-1, 0]), quiet)
            except BaseException as err:  # noqa: B902  (raised again in the caller's thread)
                self._error = err
            finally:
                self._queue.task_done()

    def _raise(self, quiet: bool) -> None:
        if self._error is not None and not quiet:
            err, self._error = self._error, _Reported(self._error)
            if not isinstance(err, _Reported):
                raise err

    def finish(self, quiet: bool = False) -> None:
        """Wait until every block handed over is on disk; raise the failure of one (unless ``quiet``)."""
        if self._thread is not None:
            self._queue.join()
        self._raise(quiet)

    def close(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None
        super().close()


class _Reported:
    """A failure of the writing thread already raised: later blocks are dropped, not reported again."""

    def __init__(self, err: BaseException):
        self.err = err


def format_csv_rows(block: np.ndarray, line: str | None = None) -> bytes:
    """The rows of ``block`` (n x columns, float64) as CSV lines, every value the shortest
    text that reads back to the same double (see CsvBlocks); ``line`` is the %-format of
    one row used for a block with a non-finite value (orjson writes those as null)."""
    block = np.ascontiguousarray(block, dtype=np.float64)
    if not np.isfinite(block).all():
        line = line or ",".join(["%r"] * block.shape[1]) + "\n"
        return ((line * block.shape[0]) % tuple(block.ravel().tolist())).encode()
    text = orjson.dumps(block, option=orjson.OPT_SERIALIZE_NUMPY)  # b"[[a,b],[c,d]]"
    # split and join: a third less time than bytes.replace of the three-byte row separator
    return b"\n".join(text[2:-2].split(b"],[")) + b"\n"


def mat_names(columns) -> list[str]:
    """MATLAB variable names of result columns: "." and anything else not allowed as "_",
    a leading "v_" if the name does not start with a letter, at most 63 characters,
    and "_2", "_3", ... for a name that would repeat an earlier one."""
    names, seen = [], set()
    for col in columns:
        base = re.sub(r"\W", "_", col, flags=re.ASCII)
        base = base if base[:1].isalpha() and base.isascii() else "v_" + base
        name, k = base[:63], 2
        while name in seen:
            name, k = f"{base[:60]}_{k}", k + 1
        seen.add(name)
        names.append(name)
    return names


class MatBlocks(_Blocks):
    """results.mat via results.part.npy: each block is appended to the .npy file as raw
    little-endian float64 rows and its header (numpy.lib.format, version 1.0, padded so that
    any row count fits in the same bytes) is rewritten with the new row count, so the part
    file is a valid .npy of the whole blocks at every moment. finish() writes results.mat
    from it (scipy.io.savemat, under a temporary name, then os.replace) and removes it."""

    def __init__(self, out: Path, columns):
        super().__init__(Path(out) / PART_FILE, columns)
        self.mat = Path(out) / FORMATS["mat"]
        self._append(self._header(0), 0, None, quiet=False)

    def _header(self, rows: int) -> bytes:
        buffer = io.BytesIO()
        npy.write_array_header_1_0(buffer, {"descr": "<f8", "fortran_order": False,
                                            "shape": (rows, len(self.columns))})
        return buffer.getvalue()

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        """Append the rows of ``block`` (n x columns) and record them in the header."""
        if not block.shape[0]:
            return
        data = np.ascontiguousarray(block, dtype="<f8").tobytes()
        if self._append(data, block.shape[0], float(block[-1, 0]), quiet):
            try:
                os.pwrite(self.fd, self._header(self.rows), 0)
            except OSError as err:  # the header is rewritten in place: it never needs new space
                if not quiet:
                    raise _write_error(self.path, err) from err

    def finish(self, quiet: bool = False) -> None:
        """Write results.mat from the whole blocks on disk and remove the part file; if that
        fails, results.part.npy stays (ResultsWriteError unless ``quiet``)."""
        try:
            write_mat(self.mat, self.columns, np.load(self.path, mmap_mode="r"))
        except (OSError, ValueError) as err:
            if quiet:
                return
            if isinstance(err, OSError):
                raise _write_error(self.mat, err, f": the rows stay in {self.path}") from err
            raise
        self.path.unlink(missing_ok=True)

    def record(self) -> None:
        return None  # the part file's header is rewritten in place: hashed from the file when needed


class Keeping:
    """A result writer that also keeps copies of the blocks it writes in ``rows`` while they
    total at most ``limit`` bytes (then ``rows`` is emptied and nothing more is kept)."""

    def __init__(self, writer, rows: list, limit: int):
        self.writer, self.rows, self.limit, self.size = writer, rows, limit, 0

    def write(self, block: np.ndarray, quiet: bool = False) -> None:
        self.writer.write(block, quiet)
        if self.size <= self.limit:
            self.size += block.nbytes
            if self.size <= self.limit:
                self.rows.append(block.copy())
            else:
                self.rows.clear()

    def finish(self, quiet: bool = False) -> None:
        self.writer.finish(quiet)

    def close(self) -> None:
        self.writer.close()


def write_mat(path: Path, columns, data: np.ndarray) -> None:
    """Write rows ``data`` (n x columns) as a MAT-file (version 5, uncompressed, readable
    by MATLAB's load, scipy.io.loadmat): one n x 1 double variable per column (mat_names)
    and ``columns``, the original names as a char matrix (MATLAB: cellstr(columns)).
    Written atomically (folders.atomic_file)."""
    from scipy.io import savemat
    variables = {name: data[:, j:j + 1] for j, name in enumerate(mat_names(columns))}
    variables["columns"] = np.array(list(columns))
    with atomic_file(path, "wb") as f:
        savemat(f, variables, do_compression=False, oned_as="column")
