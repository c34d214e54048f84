"""Finnish-Swedish Ice Class Rules (2017): brash-ice channel resistance R_CH and required engine output.

Imports nothing from the engine.
"""
