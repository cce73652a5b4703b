"""Strict YAML reading shared by every configuration file: errors name the file and the key.

Text files (configs here, marker CSVs in :mod:`.markers`) are read as UTF-8 through :func:`decode_text`: a
byte-order mark from a spreadsheet is dropped, Windows line ends are accepted, and a binary or non-UTF-8
file is named as such (with the offending byte and its line) instead of ending in a traceback.
"""
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


class TextDecodeError(ValueError):
    """Bytes that are not a UTF-8 text file: ``line`` (1-based) of the first offending byte and the problem."""

    def __init__(self, line: int, problem: str):
        self.line, self.problem = line, problem
        super().__init__(f"line {line}: {problem}")


def decode_text(data: bytes) -> str:
    """UTF-8 text of a file's bytes, without a leading byte-order mark.

    Parameters
    ----------
    data : bytes
        The file's content.

    Returns
    -------
    str
        The decoded text (line ends as in the file; ``csv`` and YAML readers accept CRLF).

    Raises
    ------
    TextDecodeError
        A NUL byte (a binary file) or a byte sequence that is not UTF-8, with its line.
    """
    nul = data.find(b"\x00")
    if nul >= 0:
        raise TextDecodeError(data.count(b"\n", 0, nul) + 1, "NUL byte: a binary file, not a UTF-8 text file")
    body = data[3:] if data.startswith(b"\xef\xbb\xbf") else data
    try:
        return body.decode("utf-8")
    except UnicodeDecodeError as e:
        raise TextDecodeError(body.count(b"\n", 0, e.start) + 1,
                              f"not a UTF-8 text file (byte 0x{body[e.start]:02x}); save it as UTF-8") from None


def read_text(path) -> str:
    """Text of an existing file through :func:`decode_text`; raises :class:`TextDecodeError`."""
    return decode_text(Path(path).read_bytes())


def load_yaml(path) -> dict:
    path = Path(path)
    if path.is_dir():
        raise ConfigError(path, None, "is a folder, not a file (expected a YAML config)")
    if not path.is_file():
        raise ConfigError(path, None, "file not found")
    try:
        text = read_text(path)
    except TextDecodeError as e:
        raise ConfigError(path, None, str(e)) from None
    try:
        data = yaml.safe_load(text)
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

    def boolean(self, name: str, default=None, required=False):
        v = self.raw(name, default, required)
        if v is None:
            return None
        if not isinstance(v, bool):
            raise ConfigError(self.path, self.key(name), f"must be true or false, got {v!r}")
        return v

    def section(self, name: str) -> "Section":
        return Section(self.path, self.raw(name, {}), self.key(name))

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            raise ConfigError(self.path, self.key(str(unknown[0])), "unknown key")
