"""Lattice Boltzmann operators: collision (cumulant, BGK), streaming, boundaries, forcing."""
