"""The package version, in a module of its own that imports nothing.

It sits below every layer (see ``tests/test_layers.py``) so that any module may record the version
without importing the package's top level.
"""
__version__ = "0.1.0"
