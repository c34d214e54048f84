"""Rigid ice floes and the ship as clumps of spheres with discrete-element contacts (paper section 2.3).

Public API::

    from iceresist.dem import DEMSystem, ContactParameters, Water, box, sphere, convex_polyhedron
"""

from iceresist.dem.bodies import RigidShape, box, convex_polyhedron, mesh_solid, sphere
from iceresist.dem.contact import ContactParameters
from iceresist.dem.hydro import Water
from iceresist.dem.system import DEMSystem

__all__ = ["DEMSystem", "ContactParameters", "Water", "RigidShape", "box", "sphere", "convex_polyhedron", "mesh_solid"]
