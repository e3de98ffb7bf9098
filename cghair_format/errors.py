"""Exceptions raised by the codec.

Every problem with a file or an asset raises a subclass of :class:`CghError`, with a message
that says what is wrong and, for files, where (chunk name, byte offset).
"""

from __future__ import annotations


class CghError(Exception):
    """Base class of every error this package raises on purpose."""


class CghFormatError(CghError):
    """A .cgh byte stream is malformed. ``offset`` and ``chunk`` say where, when known."""

    def __init__(self, message: str, *, offset: int | None = None, chunk: str | None = None):
        where = []
        if chunk is not None:
            where.append(f"chunk {chunk!r}")
        if offset is not None:
            where.append(f"byte offset {offset}")
        super().__init__(f"{message} ({', '.join(where)})" if where else message)
        self.message = message
        self.offset = offset
        self.chunk = chunk

    def at(self, offset: int) -> CghFormatError:
        """The same error placed at byte ``offset`` of the file (a decoder that knew only the chunk)."""
        return type(self)(self.message, offset=offset, chunk=self.chunk)


class TruncatedError(CghFormatError):
    """The file ends before a structure it declares."""


class BadMagicError(CghFormatError):
    """The file does not start with the .cgh magic: it is not a .cgh file."""


class UnsupportedVersionError(CghFormatError):
    """The file's major version is newer than this reader."""


class ChecksumError(CghFormatError):
    """A chunk's stored checksum does not match its bytes."""


class UnknownRequiredChunkError(CghFormatError):
    """The file needs a chunk type this reader does not know."""


class LimitError(CghFormatError):
    """A declared count or size exceeds the format's limits or the file's length."""


class InvalidContentError(CghFormatError):
    """The chunks parse, but their contents are inconsistent (bad index, non-finite value, ...)."""


class OutputError(CghError):
    """An output file or folder cannot be written (a missing or read-only folder, a file in the way)."""


class AssetError(CghError, ValueError):
    """An in-memory :class:`HairAsset` is inconsistent; raised by ``validate()``."""


class MissingDependencyError(CghError, ImportError):
    """An optional package is needed for this feature; the message names the extra to install."""

    def __init__(self, package: str, extra: str, feature: str):
        super().__init__(
            f"{feature} needs the optional package '{package}'. "
            f"Install it with: pip install 'cghair[{extra}]'"
        )
        self.package = package
        self.extra = extra


def require(module: str, extra: str, feature: str, package: str | None = None):
    """Import an optional module, or raise :class:`MissingDependencyError` naming the extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingDependencyError(package or module, extra, feature) from exc
