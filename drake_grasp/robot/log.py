"""Logging defaults for programs, workers and notebooks."""

import contextlib
import logging
import multiprocessing
import os
import sys
from collections.abc import Iterator, Mapping

# Warnings that say nothing a user can act on: an arm's OBJ meshes bring their own .mtl colours and
# the URDF names a colour too; Drake uses the file's and says so once per mesh and process.
_log = logging.getLogger(__name__)
HARMLESS_DRAKE_WARNINGS = ("has its own materials, but material properties have been defined as well",)


def _actionable(record: logging.LogRecord) -> bool:
    message = record.getMessage()
    return not any(text in message for text in HARMLESS_DRAKE_WARNINGS)


PACKAGE_LOGGER = "drake_grasp"  # every module logs under it (`logging.getLogger(__name__)`)


class _ProgramOutput(logging.Handler):
    """The package's records on this process's stderr as a program's lines: the message, "warning: " or
    "error: " before it at those levels. It writes to whatever `sys.stderr` is at the time (a test's
    capture, a notebook's cell)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            prefix = ("error: " if record.levelno >= logging.ERROR
                      else "warning: " if record.levelno >= logging.WARNING else "")
            sys.stderr.write(f"{prefix}{record.getMessage()}\n")
            sys.stderr.flush()
        except Exception:
            self.handleError(record)


def program_logging(level: int = logging.INFO) -> None:
    """Logging for a program, a worker process or a notebook: the package's notes and warnings (`level`
    and up) on stderr; Drake's INFO lines (context parallelism and the like) and its harmless warnings,
    noise for our users, dropped. Safe to call again."""
    import pydrake.common  # noqa: F401  (its import sets the level to INFO: it must come first)

    logger = logging.getLogger("drake")
    logger.setLevel(logging.WARNING)
    if _actionable not in logger.filters:
        logger.addFilter(_actionable)
    package = logging.getLogger(PACKAGE_LOGGER)
    package.setLevel(level)
    if not any(isinstance(h, _ProgramOutput) for h in package.handlers):
        package.addHandler(_ProgramOutput())
        package.propagate = False  # (a root handler would print each line twice)


SHOW_PARSER_WARNINGS = "DRAKE_GRASP_PARSER_WARNINGS"  # "all": every parser warning, as Drake words it
_summarised: set[str] = set()  # labels summarised in this process
_reported: set[str] = set()  # warnings counted in a summary already (an arm's, again in the scene's)


@contextlib.contextmanager
def parser_warnings(label: str, *, renames: Mapping[str, str] | None = None) -> Iterator[None]:
    """Drake's warnings while parsing `label`'s models, summarised in one line (once per label, in the
    main process, leaving out warnings a summary counted already; workers stay quiet), or all shown
    with DRAKE_GRASP_PARSER_WARNINGS=all. `renames` maps a prepared copy's path to the user's file,
    so that every line names the user's file."""
    logger = logging.getLogger("drake")
    show_all = os.environ.get(SHOW_PARSER_WARNINGS, "") == "all"
    caught: list[str] = []

    def capture(record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        message = record.getMessage()
        for copy, original in (renames or {}).items():
            message = message.replace(copy, original)
        if show_all:
            record.msg, record.args = message, ()
            return True
        caught.append(message)
        return False

    logger.addFilter(capture)
    try:
        yield
    finally:
        logger.removeFilter(capture)
        new = [message for message in caught if message not in _reported]
        if new and label not in _summarised and multiprocessing.parent_process() is None:
            _summarised.add(label)
            _reported.update(new)
            first = " ".join(new[0].split())
            first = first if len(first) <= 160 else first[:157] + "..."
            _log.warning(f"Drake's parser warned {len(new)} time(s) about {label}, e.g. \"{first}\"; "
                         f"{SHOW_PARSER_WARNINGS}=all shows every warning")
