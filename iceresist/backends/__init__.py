"""Compute targets: one scalar kernel source compiled for the CPU (numba) and the GPU (numba-cuda)."""

from iceresist.backends.jit import Target, cpu, cuda, cuda_available, resolve_backend, real_type

__all__ = ["Target", "cpu", "cuda", "cuda_available", "resolve_backend", "real_type"]
