"""Every error and warning volseg raises on purpose, in one place (a leaf).

All are `ValueError` subclasses: bad input or usage, never a bug. The command line
turns each into one line on stderr and exit code 2; a Python caller can catch
`VolsegError` for all of them.
"""

__all__ = ["VolsegError", "UsageError", "VolumeFileError", "MissingChunksError", "OutputError",
           "DatasetError", "EngineError", "VolsegWarning", "VolsegDeprecationWarning"]


class VolsegError(ValueError):
    """Base of the errors below."""


class UsageError(VolsegError):
    """An option or argument that cannot be used as given (exit code 2)."""


class VolumeFileError(VolsegError):
    """A volume file that cannot be read as it is: it names the file and the field.

    Raised by every reader for every malformed input (truncated data, a header field
    that is missing or out of range, an unknown type), never a bare numpy error.
    """


class MissingChunksError(VolumeFileError):
    """A Zarr store with chunks that were never written (``fill_missing_chunks`` reads
    them as the fill value)."""


class OutputError(VolsegError):
    """The outputs cannot be written as asked (exist, locked, not a file)."""


class DatasetError(VolsegError):
    """A dataset cannot be had: unknown name, offline, or a checksum mismatch."""


class EngineError(VolsegError):
    """The Dask engine cannot be started or reached as asked."""


class VolsegWarning(UserWarning):
    """A result volseg could make, but not as asked (fewer maxima than regions asked,
    missing chunks read as the fill value, a degenerate cut). The test suite turns
    these into errors, so a test that does not expect one fails."""


class VolsegDeprecationWarning(DeprecationWarning):
    """A volseg name or option that will go. Every deprecation volseg gives uses this
    class, so the tests can fail on ours and never on another package's."""
