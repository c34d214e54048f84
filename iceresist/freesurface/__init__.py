"""freesurface."""
