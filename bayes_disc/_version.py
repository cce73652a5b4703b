"""The package version and where its documentation lives, in a module of its own that imports nothing.

It sits below every layer (see ``tests/test_layers.py``) so that any module may record the version
without importing the package's top level.
"""
__version__ = "0.2.0"
#: the project's source repository (also ``[project.urls]`` in pyproject.toml)
SOURCE_URL = "https://github.com/bayes-disc/bayes-disc"
#: the user documentation (the ``docs/`` folder of the source repository)
DOCUMENTATION_URL = f"{SOURCE_URL}/blob/main/docs/index.md"
