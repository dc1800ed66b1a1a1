"""numba's on-disk cache, keyed by the source of the whole package.

numba stamps a cached kernel with a hash of the one file that defines it. A kernel that calls
kernels of other files (the CSS closed loop calls the sun-line filters and the albedo sums, the
particle filter calls ``core.particles``) is then loaded stale after one of those files
changed: after an edit, or after an upgrade installed over a package folder whose
``__pycache__`` keeps the caches of the old version (they are not part of the installed
files). It runs the old code, silently.

:func:`install` puts locators in front of numba's own for the functions defined in this
package. They use numba's cache folders unchanged (``NUMBA_CACHE_DIR`` when set, else the
package's ``__pycache__``, else the user-wide folder) and extend numba's stamp with
:func:`package_digest`, a SHA-256 of every ``.py`` file of the package. Any change anywhere in
the package recompiles each kernel once; kernels outside the package keep numba's rule.

``import lightcurve`` does not import numba (it stays fast): :func:`install_when_imported`
runs :func:`install` right after numba's first import, which every kernel module does before
it defines a kernel.
"""

from __future__ import annotations

import hashlib
import importlib.abc
import importlib.util
import os
import sys

__all__ = ["package_digest", "install", "install_when_imported", "installed"]

_PKG_DIR = os.path.dirname(os.path.abspath(__file__))
_DIGEST: dict[str, str] = {}
_INSTALLED = False


def package_digest(root: str | None = None) -> str:
    """SHA-256 (hex) of the relative paths and contents of every ``.py`` file under ``root``
    (default: this package), in sorted order; computed once per root and process."""
    root = os.path.abspath(root or _PKG_DIR)
    if root not in _DIGEST:
        files = []
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
            files += [os.path.join(dirpath, f) for f in filenames if f.endswith(".py")]
        h = hashlib.sha256()
        for path in sorted(files):
            h.update(os.path.relpath(path, root).replace(os.sep, "/").encode())
            h.update(b"\0")
            with open(path, "rb") as f:
                h.update(hashlib.sha256(f.read()).digest())
        _DIGEST[root] = h.hexdigest()
    return _DIGEST[root]


def _in_package(py_file) -> bool:
    try:
        return os.path.commonpath([os.path.abspath(py_file), _PKG_DIR]) == _PKG_DIR
    except ValueError:        # another drive (Windows)
        return False


def _locators():
    from numba.core import caching as c

    class _PackageStamp:
        """numba's locator for files of this package, its stamp extended by the package
        digest."""

        def get_source_stamp(self):
            return (super().get_source_stamp(), package_digest())

        @classmethod
        def from_function(cls, py_func, py_file):
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

    out = []
    for base in (c.UserProvidedCacheLocator, c.InTreeCacheLocator, c.UserWideCacheLocator):
        out.append(type("Package" + base.__name__, (_PackageStamp, base), {}))
    return c.CacheImpl, out


def install() -> bool:
    """Put the package locators in front of numba's (once). Returns False when this numba
    has no locator list to extend (then numba's own rule applies)."""
    global _INSTALLED
    if _INSTALLED:
        return True
    try:
        impl, locs = _locators()
        classes = impl._locator_classes
    except (ImportError, AttributeError):
        return False
    impl._locator_classes = locs + [k for k in classes if k not in locs]
    _INSTALLED = True
    return True


def installed() -> bool:
    """Whether :func:`install` has run in this process."""
    return _INSTALLED


class _AfterNumbaImport(importlib.abc.MetaPathFinder):
    """Finds nothing itself: on the first import of the top-level ``numba`` package it takes
    numba's own spec and makes that loader instance's ``exec_module`` run :func:`install`
    when numba has been executed, then leaves the finder list."""

    def find_spec(self, name, path=None, target=None):
        if name != "numba":
            return None
        sys.meta_path.remove(self)              # once: numba is imported once per process
        spec = importlib.util.find_spec(name)   # the finders after this one
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run = spec.loader.exec_module

        def exec_module(module):
            run(module)
            install()

        spec.loader.exec_module = exec_module   # this loader instance only
        return spec


def install_when_imported() -> None:
    """Run :func:`install` now if numba is imported, else right after its first import."""
    if "numba" in sys.modules:
        install()
    elif not any(isinstance(f, _AfterNumbaImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaImport())
