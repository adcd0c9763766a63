"""What a command writes: checked before any work, and moved into place only when it succeeds.

Each output is written under a hidden staging folder beside it (same file system, so the final
move is a rename); `commit` moves the staged files onto the user's paths, and leaving the `with`
block without committing removes them. A failed command therefore leaves nothing behind, and an
error while writing names the user's path, not a staging file.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

from ..errors import SketchRodGSError

STAGING_PREFIX = ".sketchrodgs-"


def check_folder(path: str | os.PathLike[str], option: str) -> None:
    """For a folder written into over time (the demo's, the viewer's exports), checked before any
    work: it is a folder, or can be made in an existing, writable one."""
    target = Path(path)
    if target.exists() and not target.is_dir():
        raise SketchRodGSError(f"{option} {path}: exists and is not a folder")
    parent = target if target.is_dir() else target.parent
    if not parent.is_dir():
        raise SketchRodGSError(f"{option} {path}: the folder {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SketchRodGSError(f"{option} {path}: cannot write in the folder {str(parent)!r}")


class Outputs:
    """The files and folders a command writes (see the module docstring).

    Usage::

        with Outputs() as outputs:
            image = outputs.file(args.output, "-o")    # checked now; write to `image`
            ...                                         # the work
            outputs.commit()                            # everything goes into place
    """

    def __init__(self) -> None:
        self._staged: dict[Path, Path] = {}  # user's path -> where it is written
        self._companions: dict[Path, list[Path]] = {}  # user's path -> files written beside it
        self._folders: dict[Path, Path] = {}  # user's parent folder -> its staging folder

    def file(
        self, path: str | os.PathLike[str], option: str, companions: Sequence[str | os.PathLike[str]] = ()
    ) -> Path:
        """Check that `path` can be written (its folder exists and is writable, it is not a
        folder); returns where to write it until `commit`. `option` names it in errors.
        `companions` are files the writer puts beside it (a rod file's bindings): they go with it."""
        target = Path(path)
        if target.is_dir():
            raise SketchRodGSError(f"{option} {path}: is a folder, expected a file name")
        staged = self._stage(target, option)
        self._companions[target] = [self._stage(Path(c), option) for c in companions]
        return staged

    def folder(self, path: str | os.PathLike[str], option: str) -> Path:
        """Check that the folder `path` can be made or written into; returns where to fill it
        until `commit` (which moves what it holds into `path`, made if missing)."""
        target = Path(path)
        if target.exists() and not target.is_dir():
            raise SketchRodGSError(f"{option} {path}: exists and is not a folder")
        staged = self._stage(target, option)
        self._companions[target] = []
        staged.mkdir()
        return staged

    def _stage(self, target: Path, option: str) -> Path:
        parent = target.parent
        if not parent.is_dir():
            raise SketchRodGSError(f"{option} {target}: the folder {str(parent)!r} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise SketchRodGSError(f"{option} {target}: cannot write in the folder {str(parent)!r}")
        key = parent.resolve()
        if key not in self._folders:
            self._folders[key] = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=parent))
        if target.resolve() in {t.resolve() for t in self._staged}:
            raise SketchRodGSError(f"{option} {target}: the same path is given for two outputs")
        staged = self._folders[key] / target.name
        self._staged[target] = staged
        return staged

    def commit(self, *only: str | os.PathLike[str]) -> None:
        """Move the staged outputs (all, or `only` these) onto the user's paths."""
        chosen = [Path(p) for p in only] or [t for t in self._staged if t in self._companions]
        for target in chosen:
            # companions first, as their writer does: a rod file never names missing bindings
            for path in [*(c for c in self._staged if self._staged[c] in self._companions[target]), target]:
                try:
                    self._move(self._staged[path], path)
                except OSError as err:
                    raise SketchRodGSError(f"{path}: cannot write ({err.strerror})") from None

    @staticmethod
    def _move(staged: Path, target: Path) -> None:
        if not staged.exists():
            return
        if staged.is_dir() and target.is_dir():
            for entry in staged.iterdir():  # into an existing folder: replace what it names
                existing = target / entry.name
                if existing.is_dir() and not existing.is_symlink():
                    shutil.rmtree(existing)
                os.replace(entry, existing)
        else:
            os.replace(staged, target)

    def __enter__(self) -> Outputs:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        for folder in self._folders.values():
            shutil.rmtree(folder, ignore_errors=True)
        if isinstance(error, OSError) and error.filename is not None:
            # name the user's path, not the staging file (or the writer's temporary file beside it)
            where = Path(os.fsdecode(error.filename))
            for target, staged in self._staged.items():
                if staged == where or staged in where.parents or where.name.startswith(f".{staged.name}."):
                    raise SketchRodGSError(f"{target}: cannot write ({error.strerror})") from None
