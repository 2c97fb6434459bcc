"""Reading the rows of a run folder back (results.mat, results.csv or results.part.npy)."""

import csv
import os
import re
import warnings
from pathlib import Path

import numpy as np
import orjson

from .folders import FORMATS, PART_FILE
from ..errors import UserError
from .writers import mat_names


class ResultFolderError(ValueError, UserError):
    """A folder given to read or plot is missing or holds no readable results."""


def _read_csv_rows(path: Path, n_columns: int) -> np.ndarray:
    """The rows of results.csv (n x n_columns): parsed as one JSON array by orjson (exact
    decimal-to-double conversion, about 3x faster than np.loadtxt); a file orjson cannot
    read that way (inf or nan written by repr, a ragged row) goes through np.loadtxt."""
    with open(path, "rb") as f:
        f.readline()
        text = f.read().rstrip(b"\n")
    try:
        flat = np.array(orjson.loads(b"[" + text.replace(b"\n", b",") + b"]"), dtype=float)
        if text and flat.size % n_columns == 0 and flat.size == (text.count(b"\n") + 1) * n_columns:
            return flat.reshape(-1, n_columns)
    except (orjson.JSONDecodeError, ValueError, TypeError):
        pass
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


# The columns the figures and metrics read (metrics.error_signals); the force figure finds F1..F3 itself.
ERROR_COLUMNS = ("time", *(f"trajectory.q{i}_d" for i in (1, 2, 3)), *(f"plant.q{i}_true" for i in (1, 2, 3)),
                 "trajectory.X_d", "trajectory.Z_d", "trajectory.B_d", "plant.X", "plant.Z", "plant.B")


def result_file(folder: Path, name: str) -> Path | None:
    """``folder/name`` if it exists, None if not. ResultFolderError if it is a link that leads out
    of the folder (never followed: it could name any file of the system) or not a regular file."""
    path = Path(folder) / name
    if not os.path.lexists(path):
        return None
    if path.is_symlink():
        target = path.resolve()
        if not target.is_relative_to(Path(folder).resolve()):
            raise ResultFolderError(f"{path} is a symbolic link to {target}, outside the result folder: allowed is a "
                                    "file tapmp wrote there (a link out of the folder is not followed)")
    if not path.is_file():
        raise ResultFolderError(f"{path} is not a regular file: allowed is a file tapmp wrote")
    return path


def json_object(folder: Path, name: str) -> dict:
    """The JSON object in ``folder/name`` (run.json, metrics.json), {} if it is missing; a file
    that is damaged (not a JSON object) is ResultFolderError naming it."""
    path = result_file(folder, name)
    if path is None:
        return {}
    try:
        info = orjson.loads(path.read_bytes())
    except (orjson.JSONDecodeError, OSError) as err:
        raise ResultFolderError(f"{path} is damaged: {' '.join(str(err).split()) or type(err).__name__} (allowed is "
                                "the JSON object tapmp wrote)") from None
    if not isinstance(info, dict):
        raise ResultFolderError(f"{path} is damaged: it holds a JSON {type(info).__name__}, not an object (allowed is "
                                "the JSON object tapmp wrote)")
    return info


def _damaged(path: Path, reason) -> ResultFolderError:
    text = " ".join(str(reason).split()) or type(reason).__name__
    return ResultFolderError(f"{path} is damaged: {text}")


def _read_mat(path: Path) -> tuple[list[str], np.ndarray]:
    from scipy.io import loadmat
    try:
        content = loadmat(path)
        columns = [str(c).rstrip() for c in content["columns"]]
        names = mat_names(columns)
        missing = [n for n in names if n not in content]
        if missing:
            raise ValueError(f"it has no variable {missing[0]} for column {columns[names.index(missing[0])]}")
        return columns, np.hstack([np.asarray(content[n], dtype=float).reshape(-1, 1) for n in names])
    except KeyError as err:
        raise _damaged(path, f"it has no variable {err}") from None
    except Exception as err:  # scipy raises many types for a file that is not a MAT-file
        raise _damaged(path, err) from None


def _read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            columns = next(csv.reader(f), None)
        if not columns:
            raise ValueError("it has no header line of column names")
        with warnings.catch_warnings():  # numpy warns about a file without rows: reported below instead
            warnings.simplefilter("ignore")
            return columns, _read_csv_rows(path, len(columns))
    except UnicodeDecodeError:
        raise _damaged(path, "it is not text") from None
    except (ValueError, csv.Error, OSError) as err:
        m = re.search(r"number of columns changed from (\d+) to (\d+) at row (\d+)", str(err))
        if m:  # numpy's text also suggests `usecols`, which is no advice for a result file
            raise _damaged(path, f"line {int(m[3]) + 1} holds {m[2]} values, not {m[1]} (a row cut or "
                           "garbled)") from None
        raise _damaged(path, err) from None


def _read_part(path: Path, folder: Path) -> tuple[list[str], np.ndarray]:
    info = json_object(folder, "run.json")
    columns = info.get("columns")
    if not (isinstance(columns, list) and all(isinstance(c, str) for c in columns)):
        raise ResultFolderError(f"{path} has no column names: run.json records none")
    try:
        data = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as err:  # numpy raises ValueError, OSError, EOFError, ... for a file that is not .npy
        raise _damaged(path, err) from None
    if data.ndim != 2 or data.dtype.kind not in "fiu":
        raise _damaged(path, f"it holds a {data.ndim}-D {data.dtype} array, not rows of numbers")
    return columns, np.array(data, dtype=float)


def read_results(folder: Path) -> tuple[list[str], np.ndarray]:
    """Columns and rows (n x columns, SI units, time [s] first) of a run folder, from
    results.mat, results.csv or (a killed MAT run) results.part.npy with the columns
    recorded in run.json. ResultFolderError (one line naming the file and what is wrong) if it
    holds none, or one that is damaged, is a link out of the folder, has no rows, or whose rows
    and columns disagree."""
    folder = Path(folder)
    mat, csv_path, part = (result_file(folder, n) for n in (FORMATS["mat"], FORMATS["csv"], PART_FILE))
    if mat is not None:
        path, (columns, data) = mat, _read_mat(mat)
    elif csv_path is not None:
        path, (columns, data) = csv_path, _read_csv(csv_path)
    elif part is not None:
        path, (columns, data) = part, _read_part(part, folder)
    else:
        raise ResultFolderError(f"{folder} holds no results ({', '.join(FORMATS.values())}): "
                                "allowed is a run folder written by tapmp run")
    if data.size == 0:
        raise ResultFolderError(f"{path} holds no rows (only the column names)")
    if data.ndim != 2 or data.shape[1] != len(columns):
        raise _damaged(path, f"its rows hold {data.shape[-1]} values but it names {len(columns)} columns")
    missing = [c for c in ERROR_COLUMNS if c not in columns]
    if missing:
        raise _damaged(path, f"it has no column {missing[0]} (allowed are the columns tapmp records)")
    if columns[0] != "time":
        raise _damaged(path, f"its first column is {columns[0]!r}, not time")
    return columns, data
