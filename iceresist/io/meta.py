"""Run metadata: what ran, where, on what, and how fast (stored as attributes of ``meta``)."""

from __future__ import annotations

import datetime as _dt
import os
import platform
import subprocess
from pathlib import Path

import numpy as np

import iceresist


def git_revision(path=None) -> str:
    """``git describe``-like revision of the source tree holding ``path`` (the package), or ``"unknown"``."""
    where = Path(path or Path(iceresist.__file__).resolve().parent)
    try:
        rev = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=where, capture_output=True, text=True,
                             timeout=5)
        if rev.returncode != 0:
            return "unknown"
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=where,
                               capture_output=True, text=True, timeout=5)
        return rev.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cpu_name() -> str:
    """The CPU model name (from /proc/cpuinfo where available) and the number of cores."""
    name = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    name = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{name} ({os.cpu_count()} cores)"


def device_name(backend: str) -> str:
    """A readable name of the device a backend runs on."""
    if backend == "cuda":
        try:
            from numba import cuda

            if os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1":
                return "CUDA simulator"
            dev = cuda.get_current_device()
            name = dev.name.decode() if isinstance(dev.name, bytes) else str(dev.name)
            return f"{name} (compute capability {dev.compute_capability[0]}.{dev.compute_capability[1]})"
        except Exception:  # pragma: no cover - depends on the machine
            return "CUDA device"
    return cpu_name()


def run_meta(*, scene_text: str = "", backend: str = "cpu", precision: str = "float32", cells: int = 0) -> dict:
    """Metadata known at the start of a run."""
    import numba

    return {
        "scene_toml": scene_text,
        "iceresist_version": iceresist.__version__,
        "git_revision": git_revision(),
        "backend": backend,
        "device": device_name(backend),
        "precision": precision,
        "cells": int(cells),
        "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "host": platform.node(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
    }


def leg_meta(earlier: dict | None, from_iteration: int, backend: str) -> dict:
    """``legs`` and ``legs_json`` of a run continued from a checkpoint (``earlier``: the result's meta before
    this leg, None for a new run): this leg appended with the iteration it started from, when, and on which
    code, backend and device (one result may span versions of the code and machines)."""
    import json

    history = json.loads(earlier.get("legs_json", "[]")) if earlier else []
    leg = int(earlier.get("legs", 1)) + 1 if earlier else 1
    history.append({"leg": leg, "from_iteration": int(from_iteration),
                    "started_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                    "git_revision": git_revision(), "backend": backend, "device": device_name(backend)})
    return {"legs": leg, "legs_json": json.dumps(history)}


def mlups(cells: int, steps: int, seconds: float) -> float:
    """Million lattice-cell updates per second."""
    return cells * steps / seconds / 1e6 if seconds > 0 else 0.0
