"""Logging defaults for programs, workers and notebooks."""

import logging

# Warnings that say nothing a user can act on: an arm's OBJ meshes bring their own .mtl colours and
# the URDF names a colour too; Drake uses the file's and says so once per mesh and process.
HARMLESS_DRAKE_WARNINGS = ("has its own materials, but material properties have been defined as well",)


def _actionable(record: logging.LogRecord) -> bool:
    message = record.getMessage()
    return not any(text in message for text in HARMLESS_DRAKE_WARNINGS)


def quiet_drake() -> None:
    """Drake's INFO lines (context parallelism and the like) and harmless warnings are noise for our users."""
    logger = logging.getLogger("drake")
    logger.setLevel(logging.WARNING)
    if _actionable not in logger.filters:
        logger.addFilter(_actionable)
