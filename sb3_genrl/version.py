"""The installed version of sb3-genrl (``sb3_genrl.__version__``)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("sb3-genrl")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
