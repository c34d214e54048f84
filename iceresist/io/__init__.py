"""Files the engine writes: the HDF5 result file with its XDMF sidecar, run metadata, checkpoints."""

from iceresist.io.checkpoint import read_checkpoint, write_checkpoint
from iceresist.io.hdf5 import RunFile

__all__ = ["RunFile", "read_checkpoint", "write_checkpoint"]
