"""Recording journals and exchange files (C3D, TRC, calibration files)."""

from spotlab.io.c3d_files import read_c3d, read_c3d_parameters
from spotlab.io.c3d_writer import write_c3d
from spotlab.io.trc_files import read_trc, write_trc
from spotlab.io.trial import FileFormatError, Trial

__all__ = [
    "FileFormatError",
    "Trial",
    "read_c3d",
    "read_c3d_parameters",
    "read_trc",
    "write_c3d",
    "write_trc",
]
