"""Recording journals and exchange files (C3D, TRC, calibration files)."""

from spotlab.io.c3d_files import read_c3d, read_c3d_parameters
from spotlab.io.c3d_writer import write_c3d
from spotlab.io.trc_files import read_trc, write_trc
from spotlab.io.trial import FileFormatError, Trial
from spotlab.io.trial_files import TRIAL_READERS, labelled_markers, read_trial

__all__ = [
    "TRIAL_READERS",
    "FileFormatError",
    "Trial",
    "labelled_markers",
    "read_c3d",
    "read_c3d_parameters",
    "read_trc",
    "read_trial",
    "write_c3d",
    "write_trc",
]
