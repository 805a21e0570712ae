"""The exceptions deformcal raises: every one is a ``deformcal.Error``.

The native module raises these classes by name, so a library error never reaches
Python as anything else (nor as a panic or an abort).
"""


class Error(Exception):
    """Base class of every deformcal error."""


class InputError(Error, ValueError):
    """Arrays, images or files given to deformcal that it cannot use: a wrong
    shape or dtype, NaN, object points that are not a planar grid, a malformed
    calibration.json."""


class OptionError(InputError):
    """An option (a ``[calibration]`` key of the config) that is unknown or out
    of range; the message names the key."""


class DataError(Error):
    """Observations that cannot support the calibration asked for: too few views
    or corners, degenerate poses, an initialisation that found no start."""


class SolverError(Error):
    """The solver refused or could not solve the problem."""


class CalibrationFailed(Error):
    """The calibration ran but failed its guard rails (as the command line's
    exit code 3). ``reasons`` and ``hints`` say why and what to try;
    ``result`` holds the calibration, whose ``save`` writes the ``FAILED-`` files."""

    def __init__(self, message, reasons=(), hints=(), result=None):
        super().__init__(message)
        self.reasons = list(reasons)
        self.hints = list(hints)
        self.result = result


class DetectionError(Error):
    """No usable chessboard was found in the image."""


class ExportError(Error):
    """A camera that an export format cannot hold exactly (never approximated)."""


class FileError(Error, OSError):
    """A file that cannot be read or written, or an output directory another
    run is writing."""
