"""The leaves of every refinement level as hexahedra, with an XDMF sidecar so ParaView opens the levels of a refined
run as one multiblock data set (paper section 2.5, fig. 1).

A level's leaf cells are written as an unstructured mesh when they first appear and again when they change (a
regridding run; each snapshot's level names its mesh in the attribute ``mesh``): shared corner nodes ``nodes``
(m, 3) in metres, x y z, and ``hexahedra`` (n, 8), the eight node indices of each cell in VTK's order (the bottom
face counter-clockwise, then the top face). Field values sit at the cell centres (``Center="Cell"``), one row per
leaf cell, in the order of the mesh. The sidecar is a temporal collection of spatial collections, one grid per level
named ``level_<l>``, so ParaView shows each level as a block that can be coloured, hidden or thresholded on its own.

Layout inside the run's HDF5 file (:class:`~iceresist.io.hdf5.RunFile`)::

    levels/                   attrs: levels (the levels present)
      mesh/level_1/           attrs: level, dx_m, cells_sha1
        nodes       [m, 3]    float64, metres
        hexahedra   [n, 8]    int64
      mesh/level_1_0000000200/  the same level after a regrid at iteration 200
      0000000100/             one snapshot, attrs: iteration, time_s
        level_1/              attrs: mesh (the name of its mesh group)
        level_1/rho [n]       float32
        level_1/u   [n, 3]    float32
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from iceresist.io.xdmf import attribute

#: Corner offsets of a cell in VTK hexahedron order.
HEX_CORNERS = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],
                       dtype=np.int64)



def hexahedra(cells_ijk, dx_m: float, origin_m=(0.0, 0.0, 0.0)):
    """Shared nodes (m, 3) in metres and connectivity (n, 8) of the cells ``cells_ijk`` (n, 3) (integer cell indices
    of one level, cell size ``dx_m``)."""
    cells = np.asarray(cells_ijk, dtype=np.int64).reshape(-1, 3)
    corners = cells[:, None, :] + HEX_CORNERS[None, :, :]                 # (n, 8, 3)
    span = corners.reshape(-1, 3).max(axis=0) + 1 if len(cells) else np.ones(3, dtype=np.int64)
    key = (corners[..., 2] * span[1] + corners[..., 1]) * span[0] + corners[..., 0]
    unique, inverse = np.unique(key.ravel(), return_inverse=True)
    ijk = np.stack([unique % span[0], (unique // span[0]) % span[1], unique // (span[0] * span[1])], axis=-1)
    nodes = np.asarray(origin_m, dtype=np.float64)[None, :] + ijk * float(dx_m)
    return nodes, inverse.reshape(-1, 8).astype(np.int64)


@dataclass(frozen=True)
class LevelMesh:
    level: int
    dx_m: float
    nodes: int
    cells: int
    name: str = ""

    @property
    def group(self) -> str:
        return self.name or f"level_{self.level}"


def _grid(h5_name: str, mesh: LevelMesh, arrays) -> list[str]:
    base = f"/levels/mesh/{mesh.group}"
    out = [f'        <Grid Name="level_{mesh.level}" GridType="Uniform">\n',
           f'          <Topology TopologyType="Hexahedron" NumberOfElements="{mesh.cells}">\n',
           f'            <DataItem Dimensions="{mesh.cells} 8" NumberType="Int" Precision="8" Format="HDF">'
           f'{escape(h5_name)}:{base}/hexahedra</DataItem>\n',
           '          </Topology>\n',
           '          <Geometry GeometryType="XYZ">\n',
           f'            <DataItem Dimensions="{mesh.nodes} 3" NumberType="Float" Precision="8" Format="HDF">'
           f'{escape(h5_name)}:{base}/nodes</DataItem>\n',
           '          </Geometry>\n']
    out += [attribute(h5_name, a, indent="          ") for a in arrays]
    out.append('        </Grid>\n')
    return out


def render(h5_name: str, snapshots) -> str:
    """The XDMF text: a temporal collection of ``snapshots``, pairs of an :class:`iceresist.io.xdmf.Snapshot` (whose
    arrays are (level, :class:`~iceresist.io.xdmf.Array`) pairs, the shapes (n,) or (n, 3)) and the
    :class:`LevelMesh` of each level it holds; each a spatial collection of one grid per level."""
    out = ['<?xml version="1.0" ?>\n', '<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n', '<Xdmf Version="2.0">\n',
           '  <Domain>\n', '    <Grid Name="levels" GridType="Collection" CollectionType="Temporal">\n']
    for snap, meshes in snapshots:
        out += [f'      <Grid Name="iteration_{snap.iteration}" GridType="Collection" CollectionType="Spatial">\n',
                f'        <Time Value="{snap.time_s!r}"/>\n']
        for mesh in meshes:
            out += _grid(h5_name, mesh, [a for lv, a in snap.arrays if lv == mesh.level])
        out.append('      </Grid>\n')
    out += ['    </Grid>\n', '  </Domain>\n', '</Xdmf>\n']
    return "".join(out)


def write(xdmf_path, h5_path, snapshots) -> Path:
    """Write the levels sidecar atomically (temporary name, then rename) next to the HDF5 file it points to."""
    xdmf_path = Path(xdmf_path)
    text = render(Path(h5_path).name, snapshots)
    tmp = xdmf_path.with_name(f".{xdmf_path.name}.tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, xdmf_path)
    return xdmf_path
