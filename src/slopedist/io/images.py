"""Reading one image file with a clear error (shared by the dataset and depth readers)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from slopedist.errors import InputFileError, MissingInputError


def read_image_file(path: str | Path, flags: int, what: str, not_decoded: str) -> NDArray:
    """Decode ``path`` with ``cv2.imread(path, flags)``.

    Raises:
        MissingInputError: the file does not exist (``"{what} not found: {path}"``).
        InputFileError: it cannot be decoded (message ``not_decoded``).
    """
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(f"{what} not found: {path}")
    image = cv2.imread(str(path), flags)
    if image is None:
        raise InputFileError(path, not_decoded)
    return np.asarray(image)
