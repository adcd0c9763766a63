"""A PLY header read before plyfile parses the file: both PLY readers (ply.py, compressed_ply.py)
refuse element counts that cannot fit in the file before plyfile allocates for them."""

from __future__ import annotations

import os

from ..errors import SceneFormatError

HEADER_LIMIT = 1 << 16  # a header longer than this is not a 3DGS file


def check_header(path: str | os.PathLike[str]) -> None:
    """Refuse headers whose element counts cannot fit in the file, before plyfile allocates for them."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(HEADER_LIMIT)
            size = os.fstat(stream.fileno()).st_size
    except OSError as exc:
        raise SceneFormatError(f"{path}: cannot read ({exc.strerror})") from None
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise SceneFormatError(f"{path}: not a PLY file or header not terminated within {HEADER_LIMIT} bytes")
    body = size - end
    ascii_format = b"format ascii" in head[:end]
    for line in head[:end].splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == b"element":
            try:
                count = int(parts[2])
            except ValueError:
                raise SceneFormatError(f"{path}: element {parts[1]!r} has a non-integer count") from None
            if count < 0:
                raise SceneFormatError(
                    f"{path}: element {parts[1].decode(errors='replace')} has negative count {count}"
                )
            # ASCII rows take at least 2 bytes ("0\n"), binary rows at least 1.
            if count * (2 if ascii_format else 1) > body:
                raise SceneFormatError(
                    f"{path}: header claims {count} {parts[1].decode(errors='replace')} rows "
                    f"but only {body} bytes follow it (truncated or corrupt)"
                )
