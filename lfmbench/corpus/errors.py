"""Errors of the corpus format: every corpus problem is a :class:`CorpusError` whose message names the file
or argument at fault (``docs/guide/corpus-format.md``).
"""
from __future__ import annotations

from lfmbench.fileio import AtomicWriteError

__all__ = ["CorpusError", "CorpusNotFoundError", "CorpusFileError", "CorpusChannelError", "CorpusValueError",
           "CorpusWriteError", "CorpusLockedError"]


class CorpusError(ValueError):
    """Base class of every corpus problem; the message names the file or argument at fault."""


class CorpusNotFoundError(CorpusError):
    """The corpus root or its ``manifest.json`` does not exist (tells the user how to make one)."""


class CorpusFileError(CorpusError):
    """A corpus file is missing, unreadable, truncated or has a bad checksum."""


class CorpusChannelError(CorpusError):
    """An EXR lacks expected channels / parts or has channels the metadata does not announce."""


class CorpusLockedError(CorpusError):
    """Another process is writing the corpus (the message names the folder, the holder's pid and host)."""


class CorpusValueError(CorpusError):
    """Radiance (or aux data) that is NaN, infinite or negative."""


#: Writing a corpus file failed (disk full, ...); the message names the file. Same class as
#: :class:`lfmbench.fileio.AtomicWriteError`.
CorpusWriteError = AtomicWriteError
