"""lfmbench: LED-flicker datasets with exact flicker-free ground truth, and an LFM benchmark."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("lfmbench")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0+unknown"

from lfmbench.resources import docs_url  # noqa: E402 - the URL of a documentation page

__all__ = ["__version__", "docs_url"]
