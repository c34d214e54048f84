"""The free surface (paper section 2.2): the phase field, the pooled liquid populations, the velocity extension and
reflag.

``KEY_MODULES``: the modules whose source decides the compiled free-surface launchers, the key of their on-disk
kernel cache (:mod:`iceresist.backends.cache`) with the builder's own parameters as the variant."""

from iceresist.backends import cache

KEY_MODULES = ("iceresist.freesurface.phasefield", "iceresist.freesurface.fluid", "iceresist.freesurface.pool",
               "iceresist.freesurface.extension", "iceresist.freesurface.hlattice", "iceresist.freesurface.layout",
               "iceresist.freesurface.probe", "iceresist.freesurface.bulk",
               "iceresist.lbm.stream", "iceresist.lbm.boundary", "iceresist.lbm.codegen", "iceresist.lbm.collide",
               "iceresist.lattice", "iceresist.grid.flags", "iceresist.grid.forest")


def kernel_key(target, variant: str, extra=()):
    """The on-disk cache key of a free-surface launcher family on ``target`` (None on CUDA: no disk cache)."""
    if target.is_cuda:
        return None
    return cache.fingerprint(variant, KEY_MODULES + tuple(extra))
