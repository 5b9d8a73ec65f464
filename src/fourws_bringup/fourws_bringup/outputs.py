"""A run's output folder and the errors of a run that cannot start or cannot be written.

A folder is made writable for a run (``prepare_out_dir``; docs/graph.md, "Runs"), its kind is
told from its content (``run_folder_problem``), and an ``OSError`` becomes one line
(``output_error``): a full disk is exit code 1, anything else a bad argument, 2
(docs/graph.md, "Lifecycle and bad input").
"""

from __future__ import annotations

import errno
import shutil
from collections.abc import Callable
from pathlib import Path

from fourws_common.exit_codes import ExitCode


class RunError(RuntimeError):
    """A run could not be started (bad arguments, existing output, unknown preset): exit
    code 2 (``exit_code``)."""

    exit_code = ExitCode.BAD_CONFIG


class OutputError(RunError):
    """The output could not be written for want of space (a full disk, a quota): not the
    user's argument, so exit code 1."""

    exit_code = ExitCode.ERROR


#: errors of a file system that is full, not of a bad path
NO_SPACE = frozenset({errno.ENOSPC, errno.EDQUOT})


def output_error(path: Path, exc: OSError, what: str = "cannot write") -> RunError:
    """The one-line error for an ``OSError`` on ``path``: an :class:`OutputError` naming the
    file system when it is full, a :class:`RunError` (bad argument) otherwise."""
    if exc.errno in NO_SPACE:
        return OutputError(f"{what} {path}: {exc.strerror} (the disk holding {path.parent} "
                           "is full)")
    return RunError(f"{what} {path}: {exc.strerror or exc}")


RUN_FOLDER_ENTRIES = ("metrics.json", "bag", "logs", "plots")


def run_folder_problem(folder: Path) -> str | None:
    """Why ``folder`` is not a fourws run folder, or None if it is one: it holds only what
    ``fourws run`` writes (:data:`RUN_FOLDER_ENTRIES`), among them ``metrics.json``,
    ``bag/metadata.yaml`` or ``logs/`` (a run that died before its bag had any)."""
    names = sorted(p.name for p in folder.iterdir())
    other = [n for n in names if n not in RUN_FOLDER_ENTRIES]
    if other:
        more = f" and {len(other) - 5} more" if len(other) > 5 else ""
        return f"it holds {', '.join(repr(n) for n in other[:5])}{more}"
    if not ((folder / "metrics.json").is_file() or (folder / "bag" / "metadata.yaml").is_file()
            or (folder / "logs").is_dir()):
        return "it has no metrics.json, bag/metadata.yaml or logs/"
    return None


def writable_dir(out_dir: Path) -> None:
    """Create ``out_dir`` (and its parents) if needed and check a file can be made in it;
    a ``RunError`` in one line otherwise (an existing file, a read-only place)."""
    import tempfile

    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"output folder {out_dir} is an existing file, not a folder")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out_dir):
            pass
    except OSError as exc:
        raise output_error(out_dir, exc, "cannot write output folder") from None


def prepare_out_dir(out_dir: Path, force: bool, *,
                    problem: Callable[[Path], str | None] = run_folder_problem,
                    what: str = "fourws run folder (" + ", ".join(RUN_FOLDER_ENTRIES) + ")",
                    replace: bool = True) -> None:
    """Make ``out_dir`` a writable folder for a run's output.

    An existing, non-empty folder is refused unless ``force``; with ``force`` it is emptied
    (``replace``; else its content stays for the command to overwrite) only if ``problem``
    (:func:`run_folder_problem` by default) finds it is fourws output (``what`` names the
    kind in the message). Any other folder is refused whole, nothing in it deleted.
    A file in the way, or a place that cannot be written, is a ``RunError`` too.
    """
    if out_dir.exists() and not out_dir.is_dir():
        raise RunError(f"output folder {out_dir} is an existing file, not a folder")
    try:
        non_empty = out_dir.is_dir() and any(out_dir.iterdir())
    except OSError as exc:
        raise RunError(f"cannot read output folder {out_dir}: {exc.strerror or exc}") from None
    if non_empty:
        if not force:
            raise RunError(f"output folder {out_dir} exists and is not empty; "
                           "use --force to overwrite it")
        try:
            why = problem(out_dir)
        except OSError as exc:
            why = f"cannot look inside it: {exc.strerror or exc}"
        if why is not None:
            raise RunError(f"output folder {out_dir} is not a {what}: {why}; --force replaces "
                           "only fourws output or an empty folder, so nothing was deleted")
        if replace:
            try:
                shutil.rmtree(out_dir)
            except OSError as exc:
                raise RunError(f"cannot replace output folder {out_dir}: "
                               f"{exc.strerror or exc}") from None
    writable_dir(out_dir)
