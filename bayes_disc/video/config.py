"""Strict reading of the video front end's YAML files (``TRACK.yaml``, render configs, camera files).

Every mapping is read through a :class:`Section`; keys that are not consumed are reported as unknown,
and every error is a one-line :class:`VideoInputError` naming the file and the key.
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml

from .errors import VideoInputError


def load_yaml(path) -> dict:
    """Read a YAML mapping; missing file, bad YAML and non-mapping top level are errors."""
    path = Path(path)
    if not path.is_file():
        raise VideoInputError(f"{path}: file not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        raise VideoInputError(f"{path}: {line}not valid YAML ({getattr(e, 'problem', e)})") from None
    if not isinstance(data, dict):
        raise VideoInputError(f"{path}: must be a YAML mapping at the top level")
    return data


class Section:
    """A mapping being read; :meth:`finish` reports keys that were never asked for."""

    def __init__(self, path, data, prefix: str = ""):
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise VideoInputError(f"{path}: key '{prefix}': must be a mapping, got {data!r}")
        self.path, self.data, self.prefix, self.used = Path(path), data, prefix, set()

    # -- helpers ---------------------------------------------------------------------------------------
    def key(self, name) -> str:
        return f"{self.prefix}.{name}" if self.prefix else str(name)

    def error(self, name, problem: str) -> VideoInputError:
        return VideoInputError(f"{self.path}: key '{self.key(name)}': {problem}")

    @property
    def folder(self) -> Path:
        return self.path.parent

    def has(self, name) -> bool:
        return name in self.data

    def keys(self) -> list:
        return list(self.data)

    # -- typed readers ---------------------------------------------------------------------------------
    def raw(self, name, default=None, required: bool = False):
        self.used.add(name)
        if name not in self.data:
            if required:
                raise self.error(name, "is required")
            return default
        return self.data[name]

    def number(self, name, default=None, required=False, positive=False, nonnegative=False,
               integer=False, minimum=None, maximum=None):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(name, f"must be a number, got {v!r}")
        if not math.isfinite(v):
            raise self.error(name, f"must be finite, got {v!r}")
        if integer and int(v) != v:
            raise self.error(name, f"must be a whole number, got {v!r}")
        if positive and v <= 0:
            raise self.error(name, f"must be positive, got {v!r}")
        if nonnegative and v < 0:
            raise self.error(name, f"must not be negative, got {v!r}")
        if minimum is not None and v < minimum:
            raise self.error(name, f"must be ≥ {minimum}, got {v!r}")
        if maximum is not None and v > maximum:
            raise self.error(name, f"must be ≤ {maximum}, got {v!r}")
        return int(v) if integer else float(v)

    def vector(self, name, length: int | None = None, default=None, required=False, integer=False):
        v = self.raw(name, default, required)
        if v is None:
            return None
        ok = isinstance(v, (list, tuple)) and (length is None or len(v) == length) and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)
        if ok and integer:
            ok = all(int(x) == x for x in v)
        if not ok:
            what = f"{length} " if length is not None else ""
            kind = "whole numbers" if integer else "finite numbers"
            raise self.error(name, f"must be a list of {what}{kind}, got {v!r}")
        return [int(x) for x in v] if integer else [float(x) for x in v]

    def matrix(self, name, rows: int, cols: int, default=None, required=False):
        v = self.raw(name, default, required)
        if v is None:
            return None
        ok = isinstance(v, (list, tuple)) and len(v) == rows and all(
            isinstance(r, (list, tuple)) and len(r) == cols and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in r)
            for r in v)
        if not ok:
            raise self.error(name, f"must be a {rows}×{cols} list of lists of finite numbers, got {v!r}")
        return [[float(x) for x in r] for r in v]

    def string(self, name, default=None, required=False, choices=None):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if not isinstance(v, str) or not v:
            raise self.error(name, f"must be a non-empty string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(name, f"must be one of {list(choices)}, got {v!r}")
        return v

    def boolean(self, name, default=None, required=False):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if not isinstance(v, bool):
            raise self.error(name, f"must be true or false, got {v!r}")
        return v

    def path_of(self, name, default=None, required=False, must_exist=True) -> Path | None:
        """A file path, relative paths resolved against the YAML file's folder."""
        v = self.string(name, default, required)
        if v is None:
            return None
        p = Path(v)
        if not p.is_absolute():
            p = self.folder / p
        if must_exist and not p.exists():
            raise self.error(name, f"file not found: {p}")
        return p

    def section(self, name, required=False) -> "Section":
        return Section(self.path, self.raw(name, {} if not required else None, required), self.key(name))

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            raise VideoInputError(f"{self.path}: key '{self.key(unknown[0])}': unknown key")
