"""numba's on-disk cache keyed by the whole package (lightcurve/numba_cache.py).

numba stamps a cached kernel with the hash of its own file only; a kernel that calls a kernel
of another file would be loaded stale after that file changed. These tests check that the
package's kernels carry the package digest in their stamp, that the digest follows every
file, and that kernels outside the package keep numba's own rule.
"""

from __future__ import annotations

import subprocess
import sys

import numba
import pytest

from lightcurve import numba_cache as nc


def test_package_digest_follows_every_file(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    (tmp_path / "sub" / "__pycache__").mkdir()
    (tmp_path / "sub" / "__pycache__" / "c.py").write_text("ignored\n")
    d0 = nc.package_digest(str(tmp_path))
    nc._DIGEST.clear()
    assert nc.package_digest(str(tmp_path)) == d0          # deterministic
    (tmp_path / "sub" / "__pycache__" / "c.py").write_text("changed\n")
    nc._DIGEST.clear()
    assert nc.package_digest(str(tmp_path)) == d0          # caches are not source
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")      # a callee's file changes
    nc._DIGEST.clear()
    d1 = nc.package_digest(str(tmp_path))
    assert d1 != d0
    (tmp_path / "sub" / "b.py").rename(tmp_path / "sub" / "b2.py")   # same content, renamed
    nc._DIGEST.clear()
    assert nc.package_digest(str(tmp_path)) not in (d0, d1)
    nc._DIGEST.clear()


def test_package_kernels_carry_the_package_digest():
    from lightcurve.css import sunline_ekf

    assert nc.installed()
    loc = sunline_ekf.ekf_propagate_nb._cache._impl.locator
    assert type(loc).__name__.startswith("Package")
    stamp = loc.get_source_stamp()
    assert stamp[1] == nc.package_digest()
    # numba's own stamp of the defining file is kept beside it
    base = type(loc).__mro__[2]
    assert stamp[0] == base.get_source_stamp(loc)


def test_kernels_outside_the_package_keep_numbas_rule():
    @numba.njit(cache=True)
    def outside(x):
        return x + 1

    loc = outside._cache._impl.locator
    assert not type(loc).__name__.startswith("Package")
    assert outside(1) == 2


@pytest.mark.parametrize("code", [
    "import lightcurve, sys; assert 'numba' not in sys.modules",
    "import lightcurve; from lightcurve import numba_cache as nc; import numba; "
    "assert nc.installed()",
    "import numba, lightcurve; from lightcurve import numba_cache as nc; assert nc.installed()",
])
def test_installed_after_numbas_first_import_without_importing_it(code):
    # `import lightcurve` stays free of numba; the locators go in as soon as numba is imported,
    # before or after lightcurve
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
