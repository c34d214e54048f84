"""iceresist: ice resistance of a ship in a brash-ice channel.

Engine: cumulant D3Q27 lattice Boltzmann + phase-field free surface + DEM ice
floes (Watanabe, Hu and Aoki 2023, IOP Conf. Ser.: Mater. Sci. Eng. 1288 012015),
set beside the Finnish-Swedish Ice Class Rules (package ``fsicr``).
"""

__version__ = "0.1.0"
