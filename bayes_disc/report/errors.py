"""Errors of the report front end."""
from __future__ import annotations


class ReportInputError(ValueError):
    """A missing or invalid run folder; the one-line message names the file and the problem."""

    def __init__(self, path, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{path}: {problem}")

    def __reduce__(self):
        """Pickle with both arguments (a report section built in a worker process may raise it)."""
        return type(self), (self.path, self.problem)
