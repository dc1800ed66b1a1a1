"""Hostile HDF5 files built with h5py: external links that resolve, external raw storage (on a
regular file and on a FIFO), virtual datasets (source missing and present), filter plugins and
datasets that declare far more rows than the file stores. Every HDF5 reader refuses them with
one line (lightcurve.io.safe_open.open_hdf5); `plot` and `invert` exit 2 instead of 0 on
another file's bytes.
"""

from __future__ import annotations

import os

import h5py
import numpy as np
import pytest

from hardening_util import small_curve
from lightcurve import InputError
from test_hardening_special_files import deadline, run_cli

N = 8  # rows of small_curve()


@pytest.fixture()
def good(tmp_path):
    p = tmp_path / "good.h5"
    small_curve(N).write(p)
    return p


def _copy(good, tmp_path, name):
    p = tmp_path / name
    p.write_bytes(good.read_bytes())
    return p


def _replace(path, name, make):
    """Delete dataset ``name`` of ``path`` and let ``make(h, name)`` create its replacement."""
    with h5py.File(path, "r+") as h:
        del h[name]
        make(h, name)


def _hdf5_readers():
    from lightcurve.css.recording import read_css_recording
    from lightcurve.filters.result import read_estimate
    from lightcurve.io.lightcurve_h5 import read_lightcurve
    from lightcurve.studies.runner import read_run

    return {"read_lightcurve": read_lightcurve, "read_css_recording": read_css_recording,
            "read_estimate": read_estimate, "read_run": read_run}


def _refused_by_all(path, match):
    for name, reader in _hdf5_readers().items():
        with deadline(), pytest.raises(InputError, match=match) as ei:
            reader(path)
        assert str(path) in str(ei.value), (name, str(ei.value))


def test_external_link_that_resolves_is_refused(good, tmp_path, capsys):
    """`mag` as an external link to another (valid) file's dataset: refused, not followed."""
    other = _copy(good, tmp_path, "other.h5")
    p = _copy(good, tmp_path, "elink.h5")
    _replace(p, "mag", lambda h, n: h.__setitem__(n, h5py.ExternalLink(str(other), "/mag")))
    with h5py.File(p, "r") as h:  # h5py itself follows it: the link is real and resolves
        assert h["mag"].shape == (N,)
    _refused_by_all(p, "external link")
    code, err = run_cli(["plot", p, "-o", tmp_path / "x.png"], capsys)
    assert code == 2 and "external link" in err


def test_external_raw_storage_is_refused(good, tmp_path, capsys):
    """`mag` stored in another file's bytes: `plot` and `invert` used to exit 0 on them."""
    victim = tmp_path / "victim.bin"
    victim.write_bytes(np.full(N, 7.25).tobytes())
    p = _copy(good, tmp_path, "extstore.h5")
    _replace(p, "mag", lambda h, n: h.create_dataset(n, shape=(N,), dtype="<f8",
                                                     external=[(str(victim), 0, 8 * N)]))
    with h5py.File(p, "r") as h:
        assert np.all(h["mag"][()] == 7.25)  # h5py reads the other file's bytes
    _refused_by_all(p, "external raw storage")
    code, err = run_cli(["plot", p, "-o", tmp_path / "x.png"], capsys)
    assert code == 2 and "external raw storage" in err
    code, err = run_cli(["invert", p, "-o", tmp_path / "inv", "--workers", "1", "-q"], capsys)
    assert code == 2 and "external raw storage" in err
    assert not (tmp_path / "x.png").exists()


def test_external_storage_on_a_fifo_does_not_hang(good, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    p = _copy(good, tmp_path, "extfifo.h5")
    _replace(p, "mag", lambda h, n: h.create_dataset(n, shape=(N,), dtype="<f8",
                                                     external=[(str(fifo), 0, 8 * N)]))
    _refused_by_all(p, "external raw storage")


@pytest.mark.parametrize("source_present", [False, True])
def test_virtual_datasets_are_refused(good, tmp_path, source_present):
    """A VDS with a missing source silently supplies its fill value; with a present source it
    reads another file. Both refused."""
    src = tmp_path / "src.h5"
    if source_present:
        with h5py.File(src, "w") as s:
            s["x"] = np.full(N, 6.5)
    p = _copy(good, tmp_path, "vds.h5")

    def make(h, n):
        lay = h5py.VirtualLayout(shape=(N,), dtype="f8")
        lay[:] = h5py.VirtualSource(str(src), "x", shape=(N,))
        h.create_virtual_dataset(n, lay, fillvalue=7.0)

    _replace(p, "mag", make)
    with h5py.File(p, "r") as h:
        assert np.all(h["mag"][()] == (6.5 if source_present else 7.0))
    _refused_by_all(p, "virtual dataset")


def test_unknown_filter_plugin_is_refused(good, tmp_path):
    """A dataset naming HDF5 filter id 32015 (a plugin HDF5 would look for and load)."""
    p = _copy(good, tmp_path, "filter.h5")

    def make(h, n):
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_chunk((4,))
        dcpl.set_filter(32015, h5py.h5z.FLAG_OPTIONAL, (3,))
        dsid = h5py.h5d.create(h.id, n.encode(), h5py.h5t.IEEE_F64LE,
                               h5py.h5s.create_simple((N,)), dcpl=dcpl)
        h5py.Dataset(dsid)[...] = 7.0 + np.zeros(N)

    _replace(p, "mag", make)
    _refused_by_all(p, "filter id 32015")


@pytest.mark.parametrize("compressed", [False, True])
def test_never_written_huge_datasets_refused_before_reading(tmp_path, compressed, monkeypatch):
    """A ~15 KB file declaring every per-row dataset with 4.9·10⁷ rows, never written: about
    9 GB of fill values would be read before the shapes were checked. Refused from the
    declared-versus-stored sizes (and the memory estimate), nothing read."""
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "1GiB")
    n = 49_000_000
    p = tmp_path / "bomb.h5"
    kw = dict(chunks=(1 << 16,), compression="gzip") if compressed else {}
    good = small_curve(N)
    with h5py.File(p, "w") as h:
        h.attrs["format_version"] = 1
        h.attrs["epoch_utc"] = good.epoch_utc
        for name, tail in (("t", ()), ("mag", ()), ("mag_sigma", ()), ("site", ()),
                           ("geometry/r_obj_eci_m", (3,)), ("geometry/r_site_eci_m", (3,)),
                           ("geometry/r_sun_eci_m", (3,)), ("truth/q", (4,)),
                           ("truth/omega_rad_s", (3,))):
            h.create_dataset(name, shape=(n, *tail), dtype="<f8",
                             **({**kw, "chunks": (1 << 16, *tail)} if compressed else {}))
        h["sites/name"] = np.array(["socorro"], dtype=h5py.string_dtype())
        h["sites/lla_deg_m"] = np.array([[33.8, -106.7, 1500.0]])
    assert p.stat().st_size < 64 * 1024
    from lightcurve.io.lightcurve_h5 import read_lightcurve

    with deadline(), pytest.raises(InputError, match="never written"):
        read_lightcurve(p)


@pytest.mark.parametrize("compression", [None, "gzip"])
def test_partly_written_datasets_refused_constant_columns_read(tmp_path, compression):
    """A chunked dataset of which one chunk of 750 was written (the rest would read as fill
    values) is refused, plain or compressed. Compressed, its declared bytes are only ~800x what
    it stores, inside the 1100x bound that deflate's 1032:1 maximum needs: the byte bound let
    it through, the count of stored chunks does not. A fully written constant column, which
    deflate shrinks ~980:1, is read."""
    from lightcurve.io.safe_open import open_hdf5

    n, chunk = 49_152_000, 1 << 16
    p = tmp_path / "partial.h5"
    with h5py.File(p, "w") as h:
        d = h.create_dataset("mag", shape=(n,), dtype="<f8", chunks=(chunk,),
                             compression=compression)
        # one chunk of random data: stored bytes ~ declared / 750 (deflate gains little)
        d[:chunk] = np.random.default_rng(1).uniform(5.0, 9.0, chunk)
        assert 700 < d.nbytes / d.id.get_storage_size() < 1000  # inside the byte bound
    with deadline(), pytest.raises(InputError, match="declares 750 chunks but the file stores 1") as ei:
        with open_hdf5(p):
            pass
    assert str(p) in str(ei.value) and "'mag'" in str(ei.value)
    q = tmp_path / "constant.h5"
    with h5py.File(q, "w") as h:
        h.create_dataset("lit", data=np.zeros(4_000_000), chunks=(1 << 20,),
                         compression="gzip", compression_opts=9, shuffle=True)
        ratio = h["lit"].nbytes / h["lit"].id.get_storage_size()
    assert 500 < ratio < 1100, ratio
    with open_hdf5(q) as h:
        assert h["lit"].shape == (4_000_000,)


def test_declared_rows_checked_against_memory_limit(tmp_path, monkeypatch):
    """Written data within the caps but over the memory limit: refused naming the limit."""
    p = tmp_path / "big.h5"
    small_curve(N).write(p)
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "1K")
    from lightcurve.io.lightcurve_h5 import read_lightcurve

    with pytest.raises(InputError, match="LIGHTCURVE_MEMORY_LIMIT"):
        read_lightcurve(p)
    monkeypatch.setenv("LIGHTCURVE_MEMORY_LIMIT", "1G")
    assert len(read_lightcurve(p)) == N


def test_link_count_and_file_size_caps(good, tmp_path, capsys):
    """The audit's own limits: a file with more than 10,000 links (here 10,001 empty groups
    beside a valid lightcurve) and a file over 16 GiB (sparse: the size is there, the bytes
    are not) are refused with one line before any dataset is read."""
    import h5py

    from lightcurve.io import safe_open as so

    many = _copy(good, tmp_path, "many.h5")
    with h5py.File(many, "r+") as h:
        g = h.create_group("junk")
        for k in range(so.HDF5_MAX_LINKS + 1):
            g.create_group(str(k))
    from lightcurve.io.lightcurve_h5 import read_lightcurve

    with deadline(), pytest.raises(InputError, match="more than 10000 objects"):
        read_lightcurve(many)  # every reader opens through the same open_hdf5
    big = _copy(good, tmp_path, "big.h5")
    with open(big, "r+b") as fh:
        fh.truncate(so.HDF5_MAX_BYTES + 1)
    _refused_by_all(big, "file too large")
    code, err = run_cli(["plot", big, "-o", tmp_path / "x.png"], capsys)
    assert code == 2 and "file too large" in err, err
