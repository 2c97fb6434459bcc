"""Reading the rows of a run folder back (results.mat, results.csv or results.part.npy)."""

import csv
from pathlib import Path

import numpy as np
import orjson

from .folders import FORMATS, PART_FILE, read_json
from .writers import mat_names


class ResultFolderError(ValueError):
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


def read_results(folder: Path) -> tuple[list[str], np.ndarray]:
    """Columns and rows (n x columns, SI units, time [s] first) of a run folder, from
    results.mat, results.csv or (a killed MAT run) results.part.npy with the columns
    recorded in run.json. ResultFolderError names the folder if it holds none."""
    folder = Path(folder)
    mat, csv_path, part = folder / FORMATS["mat"], folder / FORMATS["csv"], folder / PART_FILE
    if mat.is_file():
        from scipy.io import loadmat
        content = loadmat(mat)
        columns = [str(c).rstrip() for c in content["columns"]]
        return columns, np.hstack([content[n] for n in mat_names(columns)]).astype(float)
    if csv_path.is_file():
        with open(csv_path) as f:
            columns = next(csv.reader(f))
        return columns, _read_csv_rows(csv_path, len(columns))
    if part.is_file():
        info = read_json(folder / "run.json") or {}
        if "columns" not in info:
            raise ResultFolderError(f"{part} has no column names: run.json records none")
        return list(info["columns"]), np.array(np.load(part, mmap_mode="r"))
    raise ResultFolderError(f"{folder} holds no results ({', '.join(FORMATS.values())}): "
                            "allowed is a run folder written by tapmp run")
