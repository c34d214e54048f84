"""XDMF 2 sidecar so ParaView (XDMF reader) opens the HDF5 field snapshots as a time series.

One uniform ``3DCoRectMesh`` grid per snapshot inside a temporal collection.
Values sit at cell centres (``Center="Cell"``), so the mesh has one more point
than cells along each axis and starts at the domain origin.

Axis order: XDMF and VTK take the *last* array index as x, so datasets are
stored as ``[z, y, x]`` (``[z, y, x, component]`` for vectors) and every
dimension list here is written z, y, x (see :mod:`iceresist.io.hdf5`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

_NUMBER_TYPES = {  # numpy dtype.str[1:] -> (XDMF NumberType, Precision)
    "f4": ("Float", 4), "f8": ("Float", 8), "u1": ("UChar", 1), "i1": ("Char", 1),
    "i4": ("Int", 4), "i8": ("Int", 8), "u4": ("UInt", 4),
}


@dataclass(frozen=True)
class Array:
    """One HDF5 dataset of a snapshot: its name, ``[z, y, x(, c)]`` shape and dtype string (``'f4'``, ``'u1'``)."""

    name: str
    h5_path: str
    shape: tuple[int, ...]
    dtype: str


@dataclass(frozen=True)
class Snapshot:
    time_s: float
    iteration: int
    arrays: tuple[Array, ...]


def attribute(h5_name: str, a: Array, indent: str = "        ") -> str:
    """The cell attribute of one dataset: a vector where its last axis holds 3 components of a grid ([z, y, x, 3])
    or of a cell list ([n, 3]), else a scalar."""
    if a.dtype not in _NUMBER_TYPES:
        raise ValueError(f"no XDMF number type for dtype {a.dtype!r} of {a.name}")
    number, precision = _NUMBER_TYPES[a.dtype]
    kind = "Vector" if len(a.shape) in (2, 4) and a.shape[-1] == 3 else "Scalar"
    dims = " ".join(str(n) for n in a.shape)
    return (f'{indent}<Attribute Name={quoteattr(a.name)} AttributeType="{kind}" Center="Cell">\n'
            f'{indent}  <DataItem Dimensions="{dims}" NumberType="{number}" Precision="{precision}" '
            f'Format="HDF">{escape(h5_name)}:{escape(a.h5_path)}</DataItem>\n'
            f'{indent}</Attribute>\n')


def render(h5_name: str, shape_cells_xyz, dx_m: float, origin_m_xyz, snapshots) -> str:
    """The XDMF text for ``snapshots`` of a uniform grid of ``shape_cells_xyz`` cells of size ``dx_m``."""
    nx, ny, nz = (int(n) for n in shape_cells_xyz)
    ox, oy, oz = (float(o) for o in origin_m_xyz)
    out = ['<?xml version="1.0" ?>\n', '<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n', '<Xdmf Version="2.0">\n',
           '  <Domain>\n', '    <Grid Name="fields" GridType="Collection" CollectionType="Temporal">\n']
    for snap in snapshots:
        out.append(f'      <Grid Name="iteration_{snap.iteration}" GridType="Uniform">\n')
        out.append(f'        <Time Value="{snap.time_s!r}"/>\n')
        out.append(f'        <Topology TopologyType="3DCoRectMesh" Dimensions="{nz + 1} {ny + 1} {nx + 1}"/>\n')
        out.append('        <Geometry GeometryType="ORIGIN_DXDYDZ">\n')
        out.append(f'          <DataItem Dimensions="3" NumberType="Float" Precision="8" Format="XML">'
                   f'{oz!r} {oy!r} {ox!r}</DataItem>\n')
        out.append(f'          <DataItem Dimensions="3" NumberType="Float" Precision="8" Format="XML">'
                   f'{dx_m!r} {dx_m!r} {dx_m!r}</DataItem>\n')
        out.append('        </Geometry>\n')
        out.extend(attribute(h5_name, a) for a in snap.arrays)
        out.append('      </Grid>\n')
    out += ['    </Grid>\n', '  </Domain>\n', '</Xdmf>\n']
    return "".join(out)


def write(xdmf_path, h5_path, shape_cells_xyz, dx_m, origin_m_xyz, snapshots) -> Path:
    """Write the sidecar atomically (temporary name, then rename) next to the HDF5 file it points to."""
    xdmf_path = Path(xdmf_path)
    text = render(Path(h5_path).name, shape_cells_xyz, dx_m, origin_m_xyz, snapshots)
    tmp = xdmf_path.with_name(f".{xdmf_path.name}.tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, xdmf_path)
    return xdmf_path
