"""Checks on the folders a command will write to, made before anything is built or written.

A folder given as an output must be a folder we can create or write in: not an existing file, not under a file,
not on a path we may not write. :func:`check_output_dir` refuses the others in one line naming the key or flag
the user wrote (``output.directory``, ``--output``) and a value that works.
"""

from __future__ import annotations

import os
from pathlib import Path

from fsicr.errors import unusable_name
from iceresist.errors import InputError


def check_output_dir(path, key: str) -> Path:
    """``path`` as a folder that exists and is writable, or can be made; else :class:`InputError` naming ``key``."""
    try:
        return _check_output_dir(path, key)
    except InputError:
        raise
    except (OSError, ValueError) as exc:  # a name the file system refuses (too long, a NUL byte)
        raise InputError(f"{key}: {unusable_name(str(path), exc, 'folder')}; give another folder with {key}, "
                         f"e.g. runs") from None


def _check_output_dir(path, key: str) -> Path:
    text = str(path)
    if not text.strip():
        raise InputError(f"{key}: empty; give a folder, e.g. runs")
    p = Path(text)
    fix = f"give another folder with {key}, e.g. runs"
    if p.exists():
        if not p.is_dir():
            raise InputError(f"{key}: {text} is a file, not a folder; {fix}")
        if not os.access(p, os.W_OK | os.X_OK):
            raise InputError(f"{key}: {text} is not writable; {fix}")
        return p
    parent = p.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{key}: {text} lies under {parent}, which is a file; {fix}")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{key}: {text} cannot be made ({parent} is not writable); {fix}")
    made = []
    try:  # the only sure test (a read-only file system, /proc): make the folders, then take them away again
        for q in reversed([q for q in [p.absolute(), *p.absolute().parents] if not q.exists()]):
            q.mkdir()
            made.append(q)
    except OSError as exc:
        raise InputError(f"{key}: {text} cannot be made ({exc.strerror}); {fix}") from None
    finally:
        for q in reversed(made):
            q.rmdir()
    return p
