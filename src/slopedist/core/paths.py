"""Paths of any bytes: how a file name that is not UTF-8 is written into text and printed, and
how it reaches a library that takes only UTF-8 names.

A POSIX file name is any bytes but ``/`` and NUL. Python holds a byte that is not UTF-8 as a
lone surrogate (U+DC80–U+DCFF, the ``surrogateescape`` rule of :func:`os.fsdecode`), which
opens the file fine but cannot be encoded as UTF-8: a text output or a terminal line holding
such a path would fail, and OpenCV, given such a name, crashes the interpreter. Here:

- :data:`PATH_BYTES_ERRORS`, the codec error handler of every text slopedist writes or prints:
  such a byte becomes the four characters ``\\xNN`` (``bad\\xffname``, what Python shows for the
  byte), any other character the encoding cannot hold ``\\uNNNN``; :func:`display_path` gives
  that text of a path;
- :func:`utf8_name`: a name OpenCV can open for a path of any bytes (the path itself when it is
  UTF-8, else a symbolic link to it with a UTF-8 name, in a private temporary folder).
"""

from __future__ import annotations

import codecs
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

PATH_BYTES_ERRORS = "slopedist-path-bytes"
"""Name of the codec error handler that writes a file-name byte that is not UTF-8 as ``\\xNN``
and any other character the encoding cannot hold as ``\\uNNNN`` (give it as ``errors=`` to
``open``, ``str.encode`` or ``TextIOWrapper.reconfigure``)."""

_ESCAPED_BYTES = range(0xDC80, 0xDD00)
"""The lone surrogates that stand for the bytes 0x80–0xFF of a file name (``surrogateescape``)."""


def _escape(char: str) -> str:
    code = ord(char)
    if code in _ESCAPED_BYTES:
        return f"\\x{code - 0xDC00:02x}"
    return char.encode("ascii", "backslashreplace").decode("ascii")


def _escape_unencodable(exc: UnicodeError) -> tuple[str, int]:
    """The codec error handler :data:`PATH_BYTES_ERRORS`."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    return "".join(_escape(c) for c in exc.object[exc.start : exc.end]), exc.end


codecs.register_error(PATH_BYTES_ERRORS, _escape_unencodable)


def display_path(path: str | os.PathLike[str]) -> str:
    """``path`` as text that any UTF-8 output can hold: a byte of the name that is not UTF-8 as
    ``\\xNN`` (``/data/bad\\xffname``); a UTF-8 path unchanged."""
    text = os.fspath(path)
    return text.encode("utf-8", PATH_BYTES_ERRORS).decode("utf-8")


def utf8_text(value: object) -> object:
    """``value`` with a string made encodable as UTF-8 (:func:`display_path`'s escapes), for a
    library that writes strings as UTF-8 (Parquet); any other value unchanged."""
    return display_path(value) if isinstance(value, str) else value


def is_utf8_path(path: str | os.PathLike[str]) -> bool:
    """Whether every byte of ``path``'s name is UTF-8 (it holds no escaped byte)."""
    try:
        os.fspath(path).encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


@contextmanager
def utf8_name(path: str | os.PathLike[str]) -> Iterator[str]:
    """A name of ``path`` for a library that takes only UTF-8 names (OpenCV's video and image
    files): ``path`` itself when it is UTF-8, else, while inside, a symbolic link to it (with
    ``path``'s suffix, in a private temporary folder), which also creates ``path`` when the
    library writes through it. The library should open the file inside the block; an open
    file stays valid after it."""
    if is_utf8_path(path):
        yield os.fspath(path)
        return
    folder = tempfile.mkdtemp(prefix="slopedist-name-")
    try:
        link = Path(folder) / f"file{Path(path).suffix}"
        if not is_utf8_path(link):  # a suffix holding such a byte itself
            link = Path(folder) / "file"
        os.symlink(os.path.abspath(os.fspath(path)), link)
        yield str(link)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
