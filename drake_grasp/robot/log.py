"""Logging defaults for programs, workers and notebooks."""

import contextlib
import logging
import multiprocessing
import os
import sys
from collections.abc import Iterator, Mapping

# Warnings that say nothing a user can act on: an arm's OBJ meshes bring their own .mtl colours and
# the URDF names a colour too; Drake uses the file's and says so once per mesh and process.
HARMLESS_DRAKE_WARNINGS = ("has its own materials, but material properties have been defined as well",)


def _actionable(record: logging.LogRecord) -> bool:
    message = record.getMessage()
    return not any(text in message for text in HARMLESS_DRAKE_WARNINGS)


def quiet_drake() -> None:
    """Drake's INFO lines (context parallelism and the like) and harmless warnings are noise for our users."""
    import pydrake.common  # noqa: F401  (its import sets the level to INFO: it must come first)

    logger = logging.getLogger("drake")
    logger.setLevel(logging.WARNING)
    if _actionable not in logger.filters:
        logger.addFilter(_actionable)


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
            print(f"note: Drake's parser warned {len(new)} time(s) about {label}, e.g. \"{first}\"; "
                  f"{SHOW_PARSER_WARNINGS}=all shows every warning", file=sys.stderr)
