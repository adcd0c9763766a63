"""Reading the project's JSON files (cameras, strokes, rods) with errors that name the file."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .errors import SketchRodGSError


def read_json(path: str | os.PathLike[str], error: type[SketchRodGSError] = SketchRodGSError) -> Any:
    """Parse the JSON file at `path`; an unreadable file or bad JSON raises `error` naming it."""
    try:
        return json.loads(Path(path).read_text())
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise error(f"{path}: not valid JSON ({exc})") from None
