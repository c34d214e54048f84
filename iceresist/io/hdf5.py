"""The result file of one run (HDF5, h5py) with its XDMF sidecar (docs/SCENES.md, "Result file").

Layout::

    meta                      attrs: scene TOML, version, git revision, backend, device, precision,
                              cells, steps, wall time, MLUPS, units ... (see :mod:`iceresist.io.meta`)
    fields/                   attrs: shape_cells (x, y, z), dx_m, origin_m, axes = "zyx"
      0000000100/             one snapshot, attrs: iteration, time_s
        rho  [z, y, x]        float32 on disk
        u    [z, y, x, 3]     float32, components (u_x, u_y, u_z)
        flags [z, y, x]       uint8
    timeseries/               one resizable 1-D (or (n, k)) dataset per column;
      iteration, time_s, ...  rows appended as the run goes
    levels/                   a refined run only: every level's leaf cells as hexahedra and their
                              snapshots, with a second sidecar <name>.levels.xdmf (:mod:`iceresist.io.levels`)

Datasets are stored ``[z, y, x]`` (x fastest) because XDMF/ParaView read the
last index as x; :meth:`RunFile.read_field` returns the ``[x, y, z]`` array the
engine uses. Every write is followed by a flush, and the XDMF sidecar is
rewritten atomically, so a run that dies leaves a readable file holding
everything written before.
"""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path

import h5py
import numpy as np

from iceresist.io import levels as io_levels
from iceresist.io import xdmf

log = logging.getLogger(__name__)

_SNAP_FMT = "{:010d}"


def _attr_value(v):
    """h5py-storable attribute: strings, numbers and arrays as they are, anything else as JSON."""
    if v is None:
        return "none"
    if isinstance(v, (str, bytes, int, float, bool, np.generic, np.ndarray)):
        return v
    if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
        return np.asarray(v)
    return json.dumps(v, default=str)


def to_disk(a: np.ndarray) -> np.ndarray:
    """``[x, y, z(, c)]`` engine array -> ``[z, y, x(, c)]`` contiguous disk array; floats become float32."""
    a = np.asarray(a)
    axes = (2, 1, 0) + tuple(range(3, a.ndim))
    out = np.ascontiguousarray(a.transpose(axes))
    if np.issubdtype(out.dtype, np.floating):
        out = out.astype(np.float32, copy=False)
    elif out.dtype == np.bool_:
        out = out.astype(np.uint8)
    return out


def from_disk(a: np.ndarray) -> np.ndarray:
    """``[z, y, x(, c)]`` disk array -> ``[x, y, z(, c)]``."""
    return np.ascontiguousarray(a.transpose((2, 1, 0) + tuple(range(3, a.ndim))))


class RunFile:
    """Context manager over one run's HDF5 file.

    ``mode``: ``"w"`` create or overwrite, ``"x"`` create and fail if it exists, ``"a"`` continue (pickup),
    ``"r"`` read. ``shape_cells``, ``dx_m`` and ``origin_m`` describe the grid (needed to write fields).
    ``locking=False`` reads a file another process is still writing (as far as it goes).
    """

    def __init__(self, path, mode: str = "r", *, shape_cells=None, dx_m: float = 1.0, origin_m=(0.0, 0.0, 0.0),
                 write_xdmf: bool = True, locking: bool = True):
        self.path = Path(path)
        self.mode = mode
        self.xdmf_path = self.path.with_suffix(".xdmf")
        self._write_xdmf = write_xdmf and mode != "r"
        self.h5 = h5py.File(self.path, mode) if locking else h5py.File(self.path, mode, locking=False)
        if mode in ("w", "x", "w-"):
            self.h5.create_group("meta")
            self.h5.create_group("timeseries")
            g = self.h5.create_group("fields")
            if shape_cells is not None:
                g.attrs["shape_cells"] = np.asarray(shape_cells, dtype=np.int64)
            g.attrs["dx_m"] = float(dx_m)
            g.attrs["origin_m"] = np.asarray(origin_m, dtype=np.float64)
            g.attrs["axes"] = "zyx"
            self.flush()
        elif mode == "a":
            for name in ("meta", "timeseries", "fields"):
                self.h5.require_group(name)

    # -- context manager ------------------------------------------------------------------------------
    def __enter__(self) -> "RunFile":
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self):
        if self.h5.id.valid:
            if self._write_xdmf:
                self.flush()
                self.write_xdmf()
                self.write_levels_xdmf()
            self.h5.close()

    def flush(self):
        self.h5.flush()

    # -- grid -----------------------------------------------------------------------------------------
    @property
    def shape_cells(self) -> tuple[int, int, int] | None:
        s = self.h5["fields"].attrs.get("shape_cells")
        return None if s is None else tuple(int(n) for n in s)

    @property
    def dx_m(self) -> float:
        return float(self.h5["fields"].attrs.get("dx_m", 1.0))

    @property
    def origin_m(self) -> tuple[float, float, float]:
        return tuple(float(o) for o in self.h5["fields"].attrs.get("origin_m", (0.0, 0.0, 0.0)))

    # -- meta -----------------------------------------------------------------------------------------
    def write_meta(self, **attrs):
        """Set attributes of ``meta`` (dicts and other objects are stored as JSON text)."""
        meta = self.h5["meta"]
        for k, v in attrs.items():
            meta.attrs[k] = _attr_value(v)
        self.flush()

    @property
    def meta(self) -> dict:
        out = {}
        for k, v in self.h5["meta"].attrs.items():
            out[k] = v.decode() if isinstance(v, bytes) else v
        return out

    def meta_object(self, key: str):
        """A meta attribute that :meth:`write_meta` stored as JSON text (a dict, a mixed list), decoded; a
        plain attribute (a number, an array) as it is. KeyError when the file has no such attribute."""
        v = self.meta[key]
        return json.loads(v) if isinstance(v, str) else v

    # -- fields ---------------------------------------------------------------------------------------
    def write_fields(self, iteration: int, time_s: float, fields: dict, units: dict | None = None):
        """One snapshot: ``fields`` maps names to ``[x, y, z]`` or ``[x, y, z, 3]`` arrays of the grid shape."""
        shape = self.shape_cells
        g = self.h5["fields"].create_group(_SNAP_FMT.format(int(iteration)))
        g.attrs["iteration"] = int(iteration)
        g.attrs["time_s"] = float(time_s)
        for name, arr in fields.items():
            arr = np.asarray(arr)
            if shape is not None and tuple(arr.shape[:3]) != shape:
                raise ValueError(f"field {name!r} has shape {arr.shape}, the grid has {shape} cells")
            ds = g.create_dataset(name, data=to_disk(arr))
            if units and name in units:
                ds.attrs["units"] = units[name]
        self.flush()
        if self._write_xdmf:
            self.write_xdmf()

    def snapshot_iterations(self) -> list[int]:
        return sorted(int(k) for k in self.h5["fields"].keys())

    def read_field(self, iteration: int, name: str) -> np.ndarray:
        """A stored field as the ``[x, y, z(, c)]`` array."""
        return from_disk(self.h5["fields"][_SNAP_FMT.format(int(iteration))][name][...])

    def snapshot_time_s(self, iteration: int) -> float:
        return float(self.h5["fields"][_SNAP_FMT.format(int(iteration))].attrs["time_s"])

    def _snapshots(self):
        snaps = []
        for key in sorted(self.h5["fields"].keys()):
            g = self.h5["fields"][key]
            arrays = tuple(xdmf.Array(n, f"/fields/{key}/{n}", tuple(ds.shape), ds.dtype.str[1:])
                           for n, ds in g.items())
            snaps.append(xdmf.Snapshot(float(g.attrs["time_s"]), int(g.attrs["iteration"]), arrays))
        return snaps

    def write_xdmf(self):
        """(Re)write the XDMF sidecar listing every snapshot in the file."""
        shape = self.shape_cells
        if shape is None:
            return None
        return xdmf.write(self.xdmf_path, self.path, shape, self.dx_m, self.origin_m, self._snapshots())

    # -- refinement levels ----------------------------------------------------------------------------
    @property
    def levels_xdmf_path(self) -> Path:
        return self.path.with_suffix(".levels.xdmf")

    def write_level_fields(self, iteration: int, time_s: float, levels, units: dict | None = None):
        """One snapshot of the leaf cells of every refinement level: ``levels`` is a list of dicts with ``level``,
        ``dx_m``, ``cells_ijk`` ((n, 3) cell indices of that level) and ``fields`` (name -> (n,) or (n, 3) array in
        the order of ``cells_ijk``). A level's mesh is written when it first appears and again whenever its leaf
        cells change (a regridding run): each snapshot's level names the mesh it sits on."""
        root = self.h5.require_group("levels")
        mesh = root.require_group("mesh")
        names = {}
        for lv in levels:
            level = int(lv["level"])
            cells = np.ascontiguousarray(lv["cells_ijk"], dtype=np.int64)
            digest = hashlib.sha1(cells.tobytes()).hexdigest()
            current = mesh.attrs.get(f"current_level_{level}")
            if current is not None and current in mesh and mesh[current].attrs.get("cells_sha1", digest) == digest:
                names[level] = current
                continue
            name = f"level_{level}" if f"level_{level}" not in mesh else f"level_{level}_{int(iteration):010d}"
            k = 1
            while name in mesh:
                name, k = f"level_{level}_{int(iteration):010d}_{k}", k + 1
            nodes, hexes = io_levels.hexahedra(cells, lv["dx_m"], self.origin_m)
            g = mesh.create_group(name)
            g.attrs["level"] = level
            g.attrs["dx_m"] = float(lv["dx_m"])
            g.attrs["cells_sha1"] = digest
            g.create_dataset("nodes", data=nodes)
            g.create_dataset("hexahedra", data=hexes)
            mesh.attrs[f"current_level_{level}"] = name
            names[level] = name
        snap = root.create_group(_SNAP_FMT.format(int(iteration)))
        snap.attrs["iteration"] = int(iteration)
        snap.attrs["time_s"] = float(time_s)
        for lv in levels:
            level = int(lv["level"])
            n = mesh[f"{names[level]}/hexahedra"].shape[0]
            lg = snap.create_group(f"level_{level}")
            lg.attrs["mesh"] = names[level]
            for fname, arr in lv["fields"].items():
                arr = np.asarray(arr)
                if arr.shape[0] != n:
                    raise ValueError(f"level {lv['level']} field {fname!r} has {arr.shape[0]} rows, the level has "
                                     f"{n} cells")
                if np.issubdtype(arr.dtype, np.floating):
                    arr = arr.astype(np.float32)
                ds = lg.create_dataset(fname, data=arr)
                if units and fname in units:
                    ds.attrs["units"] = units[fname]
        self.flush()
        if self._write_xdmf:
            self.write_levels_xdmf()

    def level_snapshot_iterations(self) -> list[int]:
        if "levels" not in self.h5:
            return []
        return sorted(int(k) for k in self.h5["levels"].keys() if k != "mesh")

    def read_level_field(self, iteration: int, level: int, name: str) -> np.ndarray:
        """A stored level field, (n,) or (n, 3), rows in the order of the level's hexahedra at that snapshot."""
        return self.h5["levels"][_SNAP_FMT.format(int(iteration))][f"level_{int(level)}"][name][...]

    def _mesh_name(self, level: int, iteration: int | None) -> str:
        if iteration is None:
            return f"level_{int(level)}"
        lg = self.h5["levels"][_SNAP_FMT.format(int(iteration))][f"level_{int(level)}"]
        return str(lg.attrs.get("mesh", f"level_{int(level)}"))

    def level_mesh(self, level: int, iteration: int | None = None):
        """(nodes (m, 3) metres, hexahedra (n, 8)) of one level: its first mesh, or the one of snapshot
        ``iteration`` (a regridding run writes a new mesh when a level's cells change)."""
        g = self.h5["levels"]["mesh"][self._mesh_name(level, iteration)]
        return g["nodes"][...], g["hexahedra"][...]

    def _drop_unused_meshes(self):
        """Delete the level meshes no snapshot sits on (those of snapshots a pickup dropped), and point each level's
        current mesh at the latest snapshot's, so that the rerun writes its meshes again where its cells differ."""
        if "levels" not in self.h5:
            return
        mesh = self.h5["levels"]["mesh"]
        used, current = set(), {}
        for key in self.level_snapshot_iterations():
            for lname, lg in self.h5["levels"][_SNAP_FMT.format(key)].items():
                name = str(lg.attrs.get("mesh", lname))
                used.add(name)
                current[int(lname.split("_")[1])] = name
        for name in [n for n in mesh.keys() if n not in used]:
            del mesh[name]
        for attr in [a for a in mesh.attrs.keys() if a.startswith("current_level_")]:
            del mesh.attrs[attr]
        for level, name in current.items():
            mesh.attrs[f"current_level_{level}"] = name

    def write_levels_xdmf(self):
        """(Re)write the levels sidecar listing every level snapshot in the file (none without levels), each level
        of each snapshot on its own mesh."""
        if "levels" not in self.h5:
            return None
        mesh = self.h5["levels"]["mesh"]
        meshes = {name: io_levels.LevelMesh(int(g.attrs["level"]), float(g.attrs["dx_m"]), g["nodes"].shape[0],
                                            g["hexahedra"].shape[0], name) for name, g in mesh.items()}
        snaps = []
        for key in sorted(k for k in self.h5["levels"].keys() if k != "mesh"):
            g = self.h5["levels"][key]
            arrays = tuple((int(lname.split("_")[1]),
                            xdmf.Array(n, f"/levels/{key}/{lname}/{n}", tuple(ds.shape), ds.dtype.str[1:]))
                           for lname, lg in g.items() for n, ds in lg.items())
            on = tuple(sorted((meshes[str(lg.attrs.get("mesh", lname))] for lname, lg in g.items()),
                              key=lambda m: m.level))
            snaps.append((xdmf.Snapshot(float(g.attrs["time_s"]), int(g.attrs["iteration"]), arrays), on))
        return io_levels.write(self.levels_xdmf_path, self.path, snaps)

    # -- time series ----------------------------------------------------------------------------------
    def append_timeseries(self, row: dict, group: str = "timeseries"):
        """Append one row; each key is a column (scalar or fixed-shape array). Missing values are NaN."""
        g = self.h5.require_group(group)
        n = self._rows(g)
        for name, value in row.items():
            v = np.asarray(value)
            if name not in g:
                dtype = np.int64 if name == "iteration" else np.float64
                fill = 0 if dtype is np.int64 else np.nan
                g.create_dataset(name, shape=(n,) + v.shape, maxshape=(None,) + v.shape, dtype=dtype,
                                 chunks=(256,) + v.shape, fillvalue=fill)
            ds = g[name]
            if ds.shape[1:] != v.shape:
                raise ValueError(f"time-series column {group}/{name} has shape {ds.shape[1:]}, got {v.shape}")
        for name in g.keys():
            ds = g[name]
            ds.resize(n + 1, axis=0)
            if name in row:
                ds[n] = row[name]
        self.flush()

    @staticmethod
    def _rows(g) -> int:
        return max((g[k].shape[0] for k in g.keys()), default=0)

    def timeseries(self, group: str = "timeseries") -> dict[str, np.ndarray]:
        g = self.h5[group]
        return {k: g[k][...] for k in g.keys()}

    # -- restart --------------------------------------------------------------------------------------
    def truncate_after(self, iteration: int):
        """Drop snapshots and time-series rows later than ``iteration`` (a pickup rewrites them)."""
        for key in list(self.h5["fields"].keys()):
            if int(key) > iteration:
                del self.h5["fields"][key]
        for key in self.level_snapshot_iterations():
            if key > iteration:
                del self.h5["levels"][_SNAP_FMT.format(key)]
        self._drop_unused_meshes()
        for gname in list(self.h5.keys()):
            g = self.h5[gname]
            if isinstance(g, h5py.Group) and "iteration" in g and isinstance(g["iteration"], h5py.Dataset):
                its = g["iteration"][...]
                keep = int(np.searchsorted(its, iteration, side="right"))
                for k in g.keys():
                    g[k].resize(keep, axis=0)
        self.flush()
        if self._write_xdmf:
            self.write_xdmf()
            self.write_levels_xdmf()


class NullRunFile:
    """What an MPI rank other than 0 holds where rank 0 holds the :class:`RunFile`: every write does nothing, the
    metadata is empty and there are no snapshots (only rank 0 writes a result; :mod:`iceresist.parallel`)."""

    meta: dict = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def snapshot_iterations(self) -> list[int]:
        return []

    def __getattr__(self, name):
        return lambda *args, **kwargs: None

