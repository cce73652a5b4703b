"""Errors of the video front end."""
from __future__ import annotations


class VideoInputError(ValueError):
    """Bad input to the video front end (missing file, bad YAML key, unknown camera, ...).

    The message is one line naming the file and/or key and the reason; the command-line interface
    prints it to stderr and exits with status 2.
    """
