"""One exception hierarchy for slopedist.

Every error a user can cause (a bad file, a bad option) derives from :class:`SlopedistError`;
the command line turns these into one clear message and exit code 2, never a traceback.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from types import ModuleType


class SlopedistError(Exception):
    """Base class of every error slopedist raises on purpose."""


class InputFileError(SlopedistError):
    """A file exists but a line or field in it is malformed.

    The message names the file, the 1-based line number and the field.
    """

    def __init__(
        self, path: str | Path, message: str, *, line: int | None = None, field: str | None = None
    ) -> None:
        self.path = Path(path)
        self.line = line
        self.field = field
        where = str(path)
        if line is not None:
            where += f", line {line}"
        if field is not None:
            where += f", field '{field}'"
        super().__init__(f"{where}: {message}")


class MissingInputError(SlopedistError):
    """An expected file or folder does not exist; the message says what was expected and where."""


class ConfigurationError(SlopedistError):
    """An option or a combination of options is invalid."""


class DataMismatchError(SlopedistError):
    """Inputs that must agree do not (e.g. fewer poses than frames, calibration vs. image size)."""


class OptionalDependencyError(SlopedistError):
    """An optional extra (onnxruntime, pyorbslam3, ...) is needed but not installed."""

    def __init__(self, package: str, extra: str, purpose: str) -> None:
        super().__init__(
            f"{purpose} needs the optional package '{package}', which is not installed; "
            f"install it with: pip install 'slopedist[{extra}]'"
        )


def import_optional(module: str, extra: str, purpose: str) -> ModuleType:
    """``module`` imported, or an :class:`OptionalDependencyError` naming the extra that
    installs it (``pip install 'slopedist[extra]'``) and what it is for."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise OptionalDependencyError(module.split(".")[0], extra, purpose) from None
