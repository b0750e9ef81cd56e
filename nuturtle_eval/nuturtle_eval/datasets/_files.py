"""File checks shared by the dataset readers: every failure is a ValueError that names the file."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from numpy.typing import NDArray


def existing_file(path: Path) -> Path:
    """``path`` itself, or a ValueError naming it when it is not a file."""
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    return path


def existing_folder(path: Path) -> Path:
    """``path`` itself, or a ValueError naming it when it is not a folder (a dataset's directory)."""
    if not path.is_dir():
        raise ValueError(f"{path}: no such folder" if not path.exists() else f"{path}: not a folder")
    return path


def read_table(path: Path, columns: int) -> NDArray[np.float64]:
    """The numbers of a whitespace-separated text file as an (N, ``columns``) float64 array, N >= 1.

    Lines starting with ``#`` are comments; CRLF and LF line endings both read.
    """
    existing_file(path)
    try:
        with warnings.catch_warnings():
            # an empty file is reported below, with the file's name
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as error:
        raise ValueError(f"{path}: not a table of {columns} numeric columns ({error})") from error
    if table.shape[0] == 0:
        raise ValueError(f"{path}: no data rows")
    if table.shape[1] != columns:
        raise ValueError(f"{path}: {table.shape[1]} columns, expected {columns}")
    return table
