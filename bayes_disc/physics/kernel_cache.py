"""On-disk cache of the compiled kernels, so that a new process does not compile them again.

A kernel's generated module (:func:`.codegen.kernel_source`) is written to
``<cache root>/kernels/bd_kernel_<key>.py`` and imported from there; its functions carry numba's
``cache=True``, so numba keeps the machine code beside it (``__pycache__``). The key is a hash of
everything the machine code depends on: the generated text, the source of the modules it imports
(arctangent, the terms' hooks), the numba, numpy, Python and bayes-disc versions and the machine type.

Cache root: ``$BAYES_DISC_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/bayes-disc``, else
``~/.cache/bayes-disc``. Files are written atomically (temporary file, then a link that never replaces
an existing file), so concurrent processes are safe. If the directory cannot be written, or a term's
hooks cannot be imported by name, the kernel is compiled in memory as before, with a warning: the
results are the same, only the compile time is not saved. Kernels of older versions are never read
again (their key differs) and not deleted either: removing the directory is always safe.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import logging
import os
import platform
import sys
import tempfile
import warnings
from pathlib import Path

import numba
import numpy as np

from . import arctan
from .codegen import KernelSource

ENV_CACHE_DIR = "BAYES_DISC_CACHE_DIR"
#: said when a kernel is compiled without the disk cache
COMPILING_IN_MEMORY = "compiling the simulator (about half a minute; not cached: every new process compiles it)"
log = logging.getLogger(__name__)


def cache_root() -> Path:
    """The cache root directory (module docstring), not necessarily existing.

    Returns
    -------
    pathlib.Path
    """
    env = os.environ.get(ENV_CACHE_DIR)
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "bayes-disc"


def kernel_key(source: KernelSource) -> str:
    """Hex digest (24 characters) identifying a kernel's machine code (module docstring).

    Parameters
    ----------
    source : KernelSource

    Returns
    -------
    str

    Raises
    ------
    OSError
        If the source of a module the kernel imports is not available.
    """
    from .._version import __version__
    h = hashlib.sha256()
    modules = {arctan.__name__: arctan}
    for hook in source.hooks:
        mod = sys.modules.get(getattr(hook, "py_func", hook).__module__)
        if mod is not None:
            modules[mod.__name__] = mod
    parts = [source.text, numba.__version__, np.__version__, sys.version, platform.machine(), __version__]
    parts += [f"{name}\n{inspect.getsource(mod)}" for name, mod in sorted(modules.items())]   # OSError: no source
    for part in parts:
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:24]


def write_once(path: Path, text: str) -> bool:
    """Write ``text`` to ``path`` atomically unless a file with that exact text is already there.

    The text goes to a temporary file in the same directory, which is then hard-linked to ``path``
    (never replacing a file another process has just written) or, where links are not supported,
    moved with :func:`os.replace`. A file at ``path`` with other content (a torn copy from an
    interrupted older writer) is replaced.

    Parameters
    ----------
    path : pathlib.Path
    text : str

    Returns
    -------
    bool
        True if this call wrote the file.

    Raises
    ------
    OSError
        If the directory cannot be written.
    """
    if path.exists() and path.read_text(encoding="utf-8") == text:
        return False
    fd, tmp = tempfile.mkstemp(prefix=path.stem + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        if path.exists():
            os.replace(tmp, path)               # wrong content: replace it
            return True
        try:
            os.link(tmp, path)
        except FileExistsError:                 # another process won the race with the same text
            return False
        except OSError:                         # no hard links here
            os.replace(tmp, path)
        return True
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _import_file(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def is_compiled(folder: Path, key: str) -> bool:
    """Whether numba's cache beside the kernel ``bd_kernel_<key>.py`` in ``folder`` holds its machine code (the
    index file ``__pycache__/bd_kernel_<key>.integrate-*.nbi`` of its entry point): loading it compiles nothing.

    Parameters
    ----------
    folder : Path
        The kernels' folder of the cache root.
    key : str
        The kernel's key (:func:`kernel_key`).

    Returns
    -------
    bool
    """
    return any((folder / "__pycache__").glob(f"bd_kernel_{key}.integrate-*.nbi"))


def compile_in_memory(source: KernelSource):
    """The ``integrate`` function of a kernel compiled without any disk cache.

    Parameters
    ----------
    source : KernelSource
        Generated with ``cache=False``.

    Returns
    -------
    numba.core.registry.CPUDispatcher
    """
    namespace = {"__name__": "bayes_disc_kernel_in_memory", "__hooks__": source.hooks}
    exec(compile(source.text, "<bayes-disc kernel>", "exec"), namespace)
    return namespace["integrate"]


def load_kernel(cached: KernelSource, uncached: KernelSource):
    """The kernel's ``integrate`` function, from the disk cache when possible.

    Parameters
    ----------
    cached, uncached : KernelSource
        The same kernel generated with ``cache=True`` and with ``cache=False``.

    Returns
    -------
    numba.core.registry.CPUDispatcher
        Compiled on first call (or loaded from numba's cache).
    """
    if not cached.importable:
        warnings.warn("a physics term's hooks cannot be imported by name (defined in __main__ or inside a "
                      "function): its kernel is compiled in memory and not cached on disk", RuntimeWarning,
                      stacklevel=3)
        log.info(COMPILING_IN_MEMORY)
        return compile_in_memory(uncached)
    try:
        key = kernel_key(cached)
    except (OSError, TypeError) as exc:
        warnings.warn(f"the source of a physics term's hooks is not available ({exc}): its kernel is compiled in "
                      "memory and not cached on disk", RuntimeWarning, stacklevel=3)
        log.info(COMPILING_IN_MEMORY)
        return compile_in_memory(uncached)
    folder = cache_root() / "kernels"
    path = folder / f"bd_kernel_{key}.py"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if write_once(path, cached.text):
            log.info("wrote kernel source %s", path)
    except OSError as exc:
        msg = (f"kernel cache directory {folder} is not writable ({exc}); compiling in memory (set "
               f"{ENV_CACHE_DIR} to a writable directory to keep compiled kernels between processes)")
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
        log.info(COMPILING_IN_MEMORY)
        return compile_in_memory(uncached)
    if not is_compiled(folder, key):
        log.info(f"compiling the simulator (once, about half a minute; its machine code is then kept in {folder} "
                 "for every later run)")
    name = f"bayes_disc_kernel_{key}"
    module = sys.modules.get(name) or _import_file(path, name)
    return module.integrate
