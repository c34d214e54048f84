"""Fluid-structure coupling of the LBM and the DEM (paper section 2.4, eqs. 16-21).

Public API::

    from iceresist.coupling import FluidStructureCoupling, Sphere, Box, ConvexPolyhedron
"""

from iceresist.coupling.coupler import FluidStructureCoupling
from iceresist.coupling.geometry import Box, ConvexPolyhedron, ConvexUnion, Sphere

__all__ = ["FluidStructureCoupling", "Sphere", "Box", "ConvexPolyhedron", "ConvexUnion"]
