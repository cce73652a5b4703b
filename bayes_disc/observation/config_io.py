"""Strict YAML reading shared by every configuration file: errors name the file and the key."""
from __future__ import annotations

import math
from pathlib import Path

import yaml


class ConfigError(ValueError):
    """A configuration problem; the message names the file and the key."""

    def __init__(self, path, key: str | None, problem: str):
        self.path, self.key, self.problem = str(path), key, problem
        where = f"{path}: key '{key}'" if key else f"{path}"
        super().__init__(f"{where}: {problem}")


def load_yaml(path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(path, None, "file not found")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        line = f"line {mark.line + 1}: " if mark is not None else ""
        raise ConfigError(path, None, f"{line}not valid YAML ({getattr(e, 'problem', e)})") from None
    if not isinstance(data, dict):
        raise ConfigError(path, None, "must be a YAML mapping at the top level")
    return data


class Section:
    """A mapping being read; every key must be consumed, leftovers are reported as unknown."""

    def __init__(self, path, data, prefix: str = ""):
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ConfigError(path, prefix or None, "must be a mapping")
        self.path, self.data, self.prefix, self.used = path, data, prefix, set()

    def key(self, name: str) -> str:
        return f"{self.prefix}.{name}" if self.prefix else name

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default=None, required: bool = False):
        self.used.add(name)
        if name not in self.data:
            if required:
                raise ConfigError(self.path, self.key(name), "is required")
            return default
        return self.data[name]

    def number(self, name: str, default=None, required=False, positive=False, nonnegative=False,
               integer=False, minimum=None, maximum=None):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ConfigError(self.path, self.key(name), f"must be a number, got {v!r}")
        if not math.isfinite(v):
            raise ConfigError(self.path, self.key(name), f"must be finite, got {v!r}")
        if integer and int(v) != v:
            raise ConfigError(self.path, self.key(name), f"must be a whole number, got {v!r}")
        if positive and v <= 0:
            raise ConfigError(self.path, self.key(name), f"must be positive, got {v!r}")
        if nonnegative and v < 0:
            raise ConfigError(self.path, self.key(name), f"must not be negative, got {v!r}")
        if minimum is not None and v < minimum:
            raise ConfigError(self.path, self.key(name), f"must be ≥ {minimum}, got {v!r}")
        if maximum is not None and v > maximum:
            raise ConfigError(self.path, self.key(name), f"must be ≤ {maximum}, got {v!r}")
        return int(v) if integer else float(v)

    def vector(self, name: str, length: int, default=None, required=False):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if not isinstance(v, (list, tuple)) or len(v) != length or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
            raise ConfigError(self.path, self.key(name), f"must be a list of {length} finite numbers, got {v!r}")
        return [float(x) for x in v]

    def string(self, name: str, default=None, required=False, choices=None):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if not isinstance(v, str) or not v:
            raise ConfigError(self.path, self.key(name), f"must be a non-empty string, got {v!r}")
        if choices is not None and v not in choices:
            raise ConfigError(self.path, self.key(name), f"must be one of {list(choices)}, got {v!r}")
        return v

    def section(self, name: str) -> "Section":
        return Section(self.path, self.raw(name, {}), self.key(name))

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            raise ConfigError(self.path, self.key(str(unknown[0])), "unknown key")
