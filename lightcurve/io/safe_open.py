"""Opening untrusted input files: regular files only, bounded sizes, no HDF5 indirections.

Every reader of the package (TOML, CSV, OBJ/STL, BRDF tables, albedo maps, HDF5) opens its
file through this module, so that one set of rules holds everywhere:

* **Regular files only.** The path is opened with ``O_RDONLY | O_NONBLOCK | O_NOCTTY`` (a FIFO
  without a writer, a terminal or a device never blocks the open) and the *opened descriptor*
  is checked with ``fstat`` (no race between a check by name and the open): FIFOs, sockets,
  character and block devices (``/dev/zero``, ``/dev/stdin``) and folders are refused with
  one line. A symbolic link is followed to its target, which must itself be a regular file.
* **Size caps on the descriptor.** ``st_size`` of the opened descriptor is compared with the
  reader's cap before anything is read (``stat()`` by name says 0 bytes for ``/dev/zero``);
  :func:`read_bytes` and :func:`read_text` read at most ``cap + 1`` bytes, so a file that grows
  while it is read is refused as well.
* **HDF5** (:func:`open_hdf5`): the file is handed to h5py as the already-checked file object
  (h5py's ``fileobj`` driver), and before any dataset is read every link in the file is
  visited once: external links, external raw storage (``external=[(file, offset, size)]``),
  virtual datasets (VDS: data from other files, or a silent fill value when a source is
  missing), filters other than deflate, shuffle, Fletcher-32 and LZF (HDF5 would load a plugin
  library for an unknown filter id) and datasets that declare more bytes than the file stores
  for them (a never-written dataset of 10⁸ rows reads as fill values from a 15 KB file), or
  chunked datasets with any chunk missing, are refused, naming the object.
  :func:`read_dataset` checks a dataset's declared size against the caller's limit and against :func:`lightcurve.memory.check_allocation` before reading it.

All refusals are :class:`~lightcurve.errors.InputError` naming the file, the field (HDF5
object) and the limit, so the command line exits 2 (docs/robustness.md).
"""

from __future__ import annotations

import contextlib
import os
import stat

from ..errors import InputError

__all__ = ["open_regular", "read_bytes", "read_text", "check_regular", "open_hdf5",
           "read_dataset", "read_attr", "TOML_MAX_BYTES", "CSV_MAX_BYTES", "MESH_MAX_BYTES",
           "BRDF_MAX_BYTES", "ALBEDO_MAX_BYTES", "HDF5_MAX_BYTES", "HDF5_MAX_LINKS",
           "HDF5_ALLOWED_FILTERS", "is_regular_file", "track_inputs", "check_not_input",
           "read_json", "JSON_MAX_BYTES"]

MiB = 1024 * 1024
#: TOML files (scenarios, shapes, materials, sites, CSS configurations and studies)
TOML_MAX_BYTES = 20 * MiB
#: CSV recordings (about 2.5 million rows of 100 characters)
CSV_MAX_BYTES = 256 * MiB
#: OBJ/STL meshes
MESH_MAX_BYTES = 200 * MiB
#: tabulated BRDF CSV files
BRDF_MAX_BYTES = 64 * MiB
#: albedo maps (CERES CSV, TOMS .dat)
ALBEDO_MAX_BYTES = 16 * MiB
#: JSON files (study and batch summaries, diagnosis results)
JSON_MAX_BYTES = 256 * MiB
#: HDF5 files (a lightcurve of the 5·10⁷-epoch cap with truth is about 8.4 GB)
HDF5_MAX_BYTES = 16 * 1024 * MiB
#: links visited in one HDF5 file (the package's files hold fewer than 40)
HDF5_MAX_LINKS = 10_000
#: HDF5 filter ids allowed in datasets: deflate (1), shuffle (2), Fletcher-32 (3), LZF (32000)
HDF5_ALLOWED_FILTERS = {1: "deflate", 2: "shuffle", 3: "fletcher32", 32000: "lzf"}
#: the largest ratio of declared to stored bytes a filtered dataset may have: deflate cannot
#: exceed 1032:1 (RFC 1951: a 258-byte match costs at least 2 bits), LZF about 88:1; shuffle
#: and Fletcher-32 do not shrink data
_MAX_FILTER_RATIO = 1100
_RATIO_SLACK_BYTES = 64 * 1024

_KINDS = ((stat.S_ISDIR, "is a directory"), (stat.S_ISFIFO, "is a FIFO (named pipe)"),
          (stat.S_ISCHR, "is a character device"), (stat.S_ISBLK, "is a block device"),
          (stat.S_ISSOCK, "is a socket"))


def _kind(mode: int) -> str:
    for test, name in _KINDS:
        if test(mode):
            return name
    return "is a special file"


def _not_regular(path, mode, what):
    return InputError(f"{_kind(mode)}, not a regular {what}", file=path,
                      allowed="a regular file")


#: (st_dev, st_ino) of the inputs read while :func:`track_inputs` is active (None: not tracking)
_INPUTS: set | None = None


@contextlib.contextmanager
def track_inputs():
    """Within the block, remember every file read through this module, so that
    :func:`check_not_input` (called by :func:`lightcurve.io.atomic.atomic_path`) refuses to
    replace one of them with an output. The command line runs every command inside it: an
    output path that names an input file (``plot leo.h5 -o leo.h5``) is an InputError (exit
    2) and the input is left as it was."""
    global _INPUTS
    old, _INPUTS = _INPUTS, set()
    try:
        yield
    finally:
        _INPUTS = old


def check_not_input(path, field: str = "output") -> None:
    """Raise InputError when ``path`` is a file read as an input while tracking (same file
    by device and inode, so links and other spellings of the name count)."""
    if not _INPUTS:
        return
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return
    if (st.st_dev, st.st_ino) in _INPUTS:
        raise InputError("the output would overwrite an input file of this command",
                         file=path, field=field, allowed="an output path that is not one of "
                         "the inputs")


def _open_fd(path, max_bytes: int, what: str, track: bool = True):
    """(fd, stat) of ``path`` opened read-only and checked on the descriptor (module doc)."""
    path = os.fspath(path)
    try:  # cheap first look by name: never even open a device or a FIFO
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError("file not found", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot read the {what}: {exc.strerror}", file=path) from None
    if not stat.S_ISREG(st.st_mode):
        raise _not_regular(path, st.st_mode, what)
    flags = (os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
             | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0))
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError("file not found", file=path) from None
    except OSError as exc:
        raise InputError(f"cannot open the {what}: {exc.strerror}", file=path) from None
    try:
        st = os.fstat(fd)  # the descriptor, not the name: the file swapped in between counts
        if not stat.S_ISREG(st.st_mode):
            raise _not_regular(path, st.st_mode, what)
        if st.st_size > max_bytes:
            raise InputError(f"{what} too large ({st.st_size} bytes)", file=path,
                             allowed=f"<= {max_bytes} bytes")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)  # ordinary reads from here on (regular file)
    except BaseException:
        os.close(fd)
        raise
    if track and _INPUTS is not None:
        _INPUTS.add((st.st_dev, st.st_ino))
    return fd, st


def check_regular(path, *, max_bytes: int, what: str = "file") -> os.stat_result:
    """Check that ``path`` is a regular file of at most ``max_bytes`` (module docstring);
    return its ``fstat``. For libraries that must open the file by name themselves: prefer
    :func:`open_regular` (no gap between the check and the open)."""
    fd, st = _open_fd(path, max_bytes, what)
    os.close(fd)
    return st


def open_regular(path, *, max_bytes: int, what: str = "file", track: bool = True):
    """Open ``path`` for binary reading after the checks of the module docstring.

    Returns a buffered binary file object (close it, e.g. ``with open_regular(...) as fh``).
    The size was checked when the file was opened; use :func:`read_bytes` when the whole file
    is wanted (it also refuses a file that grew past ``max_bytes`` meanwhile).

    Raises
    ------
    InputError
        Missing file, not a regular file (FIFO, device, socket, folder), unreadable, or larger
        than ``max_bytes``; the message names the file and the limit.
    """
    fd, _ = _open_fd(path, max_bytes, what, track)
    return os.fdopen(fd, "rb")


def _read_fd(fd, path, max_bytes, what) -> bytes:
    chunks, total = [], 0
    while True:
        try:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - total))
        except OSError as exc:
            raise InputError(f"cannot read the {what}: {exc.strerror}", file=path) from None
        if not b:
            break
        chunks.append(b)
        total += len(b)
        if total > max_bytes:
            raise InputError(f"{what} too large (grew past the limit while read)", file=path,
                             allowed=f"<= {max_bytes} bytes")
    return b"".join(chunks)


def read_bytes(path, *, max_bytes: int, what: str = "file", track: bool = True) -> bytes:
    """The whole content of a regular file of at most ``max_bytes`` (module docstring).
    ``track=False`` for the program's own state files (not inputs, see :func:`track_inputs`)."""
    fd, _ = _open_fd(path, max_bytes, what, track)
    try:
        return _read_fd(fd, os.fspath(path), max_bytes, what)
    finally:
        os.close(fd)


def read_text(path, *, max_bytes: int, what: str = "file", encoding: str = "utf-8",
              track: bool = True) -> str:
    """:func:`read_bytes` decoded; invalid text is an InputError naming the byte offset.
    ``encoding="utf-8-sig"`` drops a leading byte-order mark."""
    raw = read_bytes(path, max_bytes=max_bytes, what=what, track=track)
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", file=path) from None


def read_json(path, *, max_bytes: int = JSON_MAX_BYTES, what: str = "JSON file",
              track: bool = True):
    """A JSON document from a regular file of at most ``max_bytes``; invalid JSON (or
    nesting deeper than Python's recursion limit) is an InputError naming the file."""
    import json

    text = read_text(path, max_bytes=max_bytes, what=what, track=track)
    try:
        return json.loads(text)
    except ValueError as exc:
        raise InputError(f"not valid JSON: {exc}", file=path) from None
    except RecursionError:
        raise InputError("not valid JSON: nested too deeply", file=path) from None


# ----------------------------------------------------------------------------------------
# HDF5
# ----------------------------------------------------------------------------------------
def _audit_dataset(ds, name, path):
    """Refuse a dataset whose data would come from elsewhere or from nowhere (module doc)."""
    import h5py

    if ds.is_virtual:
        raise InputError("virtual dataset (VDS): its data would be read from other files or "
                         "replaced by a fill value; refused", file=path, field=name,
                         allowed="datasets stored in the file itself")
    if ds.external:
        raise InputError("dataset with external raw storage (data in another file); refused",
                         file=path, field=name, value=str(ds.external[0][0]),
                         allowed="datasets stored in the file itself")
    plist = ds.id.get_create_plist()
    filtered = False
    for i in range(plist.get_nfilters()):
        fid = int(plist.get_filter(i)[0])
        if fid not in HDF5_ALLOWED_FILTERS:
            raise InputError(f"dataset uses HDF5 filter id {fid} (a plugin library would be "
                             "loaded); refused", file=path, field=name,
                             allowed=", ".join(f"{v} ({k})" for k, v in HDF5_ALLOWED_FILTERS.items()))
        filtered = filtered or fid in (1, 32000)
    try:
        declared = int(ds.size) * int(ds.dtype.itemsize)
    except (TypeError, ValueError):
        declared = 0
    if declared == 0:
        return
    stored = int(ds.id.get_storage_size())
    layout = plist.get_layout()
    if layout == h5py.h5d.COMPACT:
        return  # data in the object header (< 64 KiB)
    if layout == h5py.h5d.CHUNKED:
        # every chunk must be in the file: a chunk never written reads as fill values, and a
        # compressed file could otherwise hide up to 1100x its size of them
        chunks = plist.get_chunk()
        expected = 1
        for dim, c in zip(ds.shape, chunks):
            expected *= -(-int(dim) // max(int(c), 1))
        try:
            present = int(ds.id.get_num_chunks())
        except (AttributeError, RuntimeError, ValueError):  # HDF5 < 1.10.5: the byte bound only
            present = expected
        if present < expected:
            raise InputError(f"dataset declares {expected} chunks but the file stores {present} "
                             "(never written or truncated: the rest would read as fill values)",
                             file=path, field=name, value=tuple(int(x) for x in ds.shape),
                             allowed="datasets whose data is in the file")
    limit = _MAX_FILTER_RATIO * stored + _RATIO_SLACK_BYTES if filtered else stored
    if declared > limit:
        raise InputError(f"dataset declares {declared} bytes but the file stores {stored} for "
                         "it (never written or truncated: it would read as fill values)",
                         file=path, field=name, value=tuple(int(x) for x in ds.shape),
                         allowed="datasets whose data is in the file")


def _audit_hdf5(h, path, max_links):
    """Visit every link once; refuse external links and audit every dataset."""
    import h5py

    count = [0]
    problem = []

    def visit(name, link):
        count[0] += 1
        if count[0] > max_links:
            problem.append(InputError(f"more than {max_links} objects in the file", file=path,
                                      allowed=f"<= {max_links} links"))
            return True
        if isinstance(link, h5py.ExternalLink):
            problem.append(InputError("external link to another file; refused", file=path,
                                      field=name, value=f"{link.filename}:{link.path}",
                                      allowed="objects stored in the file itself"))
            return True
        if isinstance(link, h5py.SoftLink):
            return None  # a path inside this file: resolved through audited links only
        if not isinstance(link, h5py.HardLink):
            problem.append(InputError(f"user-defined link type {type(link).__name__}; refused",
                                      file=path, field=name))
            return True
        obj = h.get(name)
        if isinstance(obj, h5py.Dataset):
            try:
                _audit_dataset(obj, name, path)
            except InputError as exc:
                problem.append(exc)
                return True
        return None

    h.visititems_links(visit)
    if problem:
        raise problem[0]


@contextlib.contextmanager
def open_hdf5(path, *, max_bytes: int = HDF5_MAX_BYTES, max_links: int = HDF5_MAX_LINKS,
              track: bool = True):
    """Open an untrusted HDF5 file read-only; yields the ``h5py.File`` (module docstring).

    Use as ``with open_hdf5(p) as h: x = read_dataset(h, "t", max_elements=..., file=p)``.

    Raises
    ------
    InputError
        Not a regular file or too large (:func:`open_regular`), not HDF5 / damaged, or an
        external link, external storage, a virtual dataset, a disallowed filter or a dataset
        declaring more bytes than it stores (the message names the object).
    """
    import h5py

    fh = open_regular(path, max_bytes=max_bytes, what="HDF5 file", track=track)
    try:
        try:
            h = h5py.File(fh, "r")
        except (OSError, RuntimeError, ValueError) as exc:
            raise InputError(f"not a readable HDF5 file (truncated or corrupted?): "
                             f"{' '.join(str(exc).split())}", file=path) from None
        with h:
            try:
                _audit_hdf5(h, path, max_links)
            except InputError:
                raise
            except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
                raise InputError(f"corrupted HDF5 structure: {' '.join(str(exc).split())}",
                                 file=path) from None
            yield h
    finally:
        fh.close()


def read_dataset(h, name: str, *, max_elements: int, file=None, required: bool = True,
                 what: str | None = None):
    """``h[name][()]`` after checking that it is a dataset of at most ``max_elements``
    elements whose bytes fit the memory limit (:func:`lightcurve.memory.check_allocation`).

    Returns None for a missing optional dataset. ``h`` must come from :func:`open_hdf5`
    (external links and hostile storage already refused).
    """
    import h5py

    from ..memory import check_allocation

    if name not in h:
        if required:
            raise InputError("missing dataset", file=file, field=name)
        return None
    d = h.get(name)
    if not isinstance(d, h5py.Dataset):
        raise InputError("expected a dataset", file=file, field=name)
    if d.size > max_elements:
        raise InputError("dataset too large (declared shape)", file=file, field=name,
                         value=tuple(int(x) for x in d.shape), allowed=f"<= {max_elements} elements")
    check_allocation(int(d.size) * int(d.dtype.itemsize), what or f"dataset '{name}'",
                     file=file, field=name)
    try:
        return d[()]
    except (OSError, RuntimeError, ValueError, TypeError) as exc:
        raise InputError(f"cannot read dataset (corrupted?): {' '.join(str(exc).split())}",
                         file=file, field=name) from None


def read_attr(obj, name: str, default=None, *, file=None, max_bytes: int = 64 * MiB):
    """Attribute ``name`` of an HDF5 object (``default`` if absent), bytes decoded to text;
    a fixed-size attribute larger than ``max_bytes`` is refused before it is read."""
    if name not in obj.attrs:
        return default
    try:
        aid = obj.attrs.get_id(name)
        if int(aid.get_storage_size()) > max_bytes:
            raise InputError("attribute too large", file=file, field=name,
                             allowed=f"<= {max_bytes} bytes")
        v = obj.attrs[name]
    except InputError:
        raise
    except (OSError, RuntimeError, ValueError, TypeError, KeyError) as exc:
        raise InputError(f"cannot read attribute (corrupted?): {' '.join(str(exc).split())}",
                         file=file, field=name) from None
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else v


def is_regular_file(path) -> bool:
    """True when ``path`` names a regular file (following links); never opens it."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False

