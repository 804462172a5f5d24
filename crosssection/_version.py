"""Package version, recorded in every output."""
from importlib.metadata import PackageNotFoundError, version as _pkg_version

try:
    __version__ = _pkg_version("foldstat")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.4.0"
