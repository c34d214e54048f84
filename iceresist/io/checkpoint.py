"""Checkpoints: a model's whole state in one HDF5 file, written so a crash never leaves a half file.

The file is written under a temporary name in the same folder, flushed and
synced, then renamed over the target with :func:`os.replace` (atomic on POSIX
and Windows). A state is a nested dict: arrays and numbers become datasets
(dtype kept bit for bit), strings become attributes, dicts become groups.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from iceresist.errors import InputError

FORMAT = "iceresist-checkpoint-1"


def _write_group(g: h5py.Group, state: dict):
    for key, value in state.items():
        if isinstance(value, dict):
            _write_group(g.create_group(key), value)
        elif isinstance(value, str):
            g.attrs[key] = value
        elif value is None:
            g.attrs[key] = "__none__"
        else:
            g.create_dataset(key, data=np.asarray(value))


def _read_group(g: h5py.Group) -> dict:
    out = {}
    for key, value in g.attrs.items():
        if key.startswith("_checkpoint_"):
            continue
        value = value.decode() if isinstance(value, bytes) else str(value)
        out[key] = None if value == "__none__" else value
    for key, item in g.items():
        if isinstance(item, h5py.Group):
            out[key] = _read_group(item)
        elif item.ndim == 0:
            out[key] = item[()]
        else:
            out[key] = item[...]
    return out


def write_checkpoint(path, state: dict) -> Path:
    """Write ``state`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with h5py.File(tmp, "w") as h5:
            h5.attrs["_checkpoint_format"] = FORMAT
            _write_group(h5, state)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def read_checkpoint(path) -> dict:
    """Read back a state written by :func:`write_checkpoint`."""
    path = Path(path)
    try:
        h5 = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{path}: cannot open the checkpoint: {exc}") from None
    with h5:
        if h5.attrs.get("_checkpoint_format") != FORMAT:
            raise InputError(f"{path}: not an iceresist checkpoint")
        return _read_group(h5)
