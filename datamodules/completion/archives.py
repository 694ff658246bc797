"""The bytes of a model file given as a path, an ``archive::member`` inside a zip (a ``.pk3`` or ``.jar``),
or bytes already read: what the AC3D and MD2 readers take."""
from __future__ import annotations

import zipfile
from pathlib import Path

from datamodules.cache import DataError


def source_bytes(source: str | Path | bytes, where: str | None = None) -> tuple[bytes, str]:
    """``(data, name for messages)``; ``where`` names bytes (default ``<bytes>``) or overrides the path.

    Raises:
        DataError: the file or the member cannot be read (the message names it).
    """
    if isinstance(source, bytes):
        return source, where or "<bytes>"
    where = where or str(source)
    try:
        if "::" in str(source):
            archive, member = str(source).split("::", 1)
            with zipfile.ZipFile(archive) as z:
                return z.read(member), where
        return Path(source).read_bytes(), where
    except (OSError, KeyError, zipfile.BadZipFile) as exc:
        raise DataError(f"{where}: cannot read ({type(exc).__name__}: {exc})") from exc
