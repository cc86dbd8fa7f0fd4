"""The output-folder guard shared by every command that writes a folder (replay, simulate, diagnose, evaluate, demo).

A command never writes into a folder that holds a field log (docs/model.md §9: ``log.csv`` or ``meta.json``,
in the folder itself or in one of its sub-folders) unless trackenv wrote that folder, or unless the
caller passes ``force=True`` (``--force`` on the command line). A folder trackenv wrote carries the
manifest ``trackenv_output.json`` (the command, the time and the trackenv version), written by
:func:`prepare_output_dir` before anything else; a folder without it is somebody's data. An output path
that is an existing file is refused too.

    from trackenv.outputs import prepare_output_dir
    out = prepare_output_dir("out/replay", "replay")         # created; OutputFolderError if it holds data
"""

from __future__ import annotations

import json
import time
from pathlib import Path

__all__ = ["MANIFEST", "OutputFolderError", "prepare_output_dir", "is_trackenv_output", "field_logs_in"]

MANIFEST = "trackenv_output.json"
_LOG_FILES = ("log.csv", "meta.json")


class OutputFolderError(ValueError):
    """An output folder would overwrite data trackenv did not write (or is a file); the message names it."""


def is_trackenv_output(folder: str | Path) -> bool:
    """True if ``folder`` carries the manifest of a trackenv command."""
    p = Path(folder) / MANIFEST
    if not p.is_file():
        return False
    try:
        return json.loads(p.read_text(encoding="utf-8")).get("written_by") == "trackenv"
    except (ValueError, OSError, AttributeError):
        return False


def field_logs_in(folder: str | Path) -> list[Path]:
    """Field-log files (``log.csv``/``meta.json``) in ``folder`` and in its direct sub-folders."""
    folder = Path(folder)
    found = [folder / f for f in _LOG_FILES if (folder / f).is_file()]
    try:
        subs = sorted(p for p in folder.iterdir() if p.is_dir())
    except OSError:
        subs = []
    for sub in subs:
        found += [sub / f for f in _LOG_FILES if (sub / f).is_file() and not is_trackenv_output(sub)]
    return found


def prepare_output_dir(folder: str | Path, command: str, *, force: bool = False, inputs=()) -> Path:
    """Create ``folder`` for ``trackenv <command>`` and mark it as trackenv output; refuse to clobber data.

    Raises :class:`OutputFolderError` when ``folder`` is an existing file, is (or contains) one of the
    ``inputs`` folders, or holds a field log that trackenv did not write (unless ``force``).
    Returns the folder as a ``Path``.
    """
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise OutputFolderError(f"{out}: the output path is an existing file, not a folder; choose another output "
                                "folder")
    for src in inputs:
        src = Path(src)
        if src.exists() and out.exists() and (out.resolve() == src.resolve() or out.resolve() in src.resolve().parents):
            raise OutputFolderError(f"{out}: the output folder is (or contains) the input {src}; choose another output "
                                    "folder (writing there would overwrite the input)")
    if out.is_dir() and not force and not is_trackenv_output(out):
        logs = field_logs_in(out)
        if logs:
            raise OutputFolderError(
                f"{out}: the output folder holds a field log trackenv did not write ({logs[0]}); refusing to "
                f"overwrite it. Choose another output folder, or pass --force (force=True) to write there anyway")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputFolderError(f"{out}: a file is in the way of the output folder; choose another one") from None
    except OSError as exc:
        raise OutputFolderError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    _write_manifest(out, command)
    return out


def _write_manifest(out: Path, command: str) -> None:
    try:
        from importlib.metadata import version

        ver = version("trackenv")
    except Exception:  # noqa: BLE001  (not installed: a source checkout)
        ver = None
    manifest = {"written_by": "trackenv", "command": command, "trackenv_version": ver,
                "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    (out / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
