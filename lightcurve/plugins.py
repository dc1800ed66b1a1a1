"""User plugins: a Python module (installed or a ``.py`` file) loaded at run time.

A plugin registers what it brings when it is imported: BRDFs with
:func:`lightcurve.photometry.register_brdf`, physics effects with
:func:`lightcurve.physics.registry.register_effect`. It may also list shape folders in a module
attribute ``SHAPE_DIRS`` (paths relative to the plugin file, or absolute); they are searched
after the folders given with ``--library`` and before the bundled ``shapes/``. The command line
loads plugins with ``lightcurve --plugin MODULE`` (repeatable, accepted before or after the
subcommand), so a custom BRDF works without packaging it as an entry point
(``docs/extending.md``).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

from .errors import InputError

__all__ = ["load_plugin", "plugin_shape_dirs", "loaded_plugins"]

_LOADED: dict[str, object] = {}
_SHAPE_DIRS: list[Path] = []


def load_plugin(spec):
    """Import plugin ``spec`` once and return the module.

    ``spec`` is a dotted module name on ``sys.path`` (``mybrdfs`` or ``mypkg.brdfs``) or the
    path of a ``.py`` file. Raises :class:`InputError` (naming ``--plugin`` and the spec) when
    the module cannot be found or fails to import; the message carries the import error.
    """
    key = str(spec)
    if key in _LOADED:
        return _LOADED[key]
    path = Path(key)
    try:
        if key.endswith(".py") or path.is_file():
            if not path.is_file():
                raise InputError("plugin file not found", field="--plugin", value=key)
            name = f"lightcurve_plugin_{path.stem}"
            sp = importlib.util.spec_from_file_location(name, path)
            if sp is None or sp.loader is None:
                raise InputError("not a Python module file", field="--plugin", value=key)
            mod = importlib.util.module_from_spec(sp)
            sys.modules[name] = mod
            sp.loader.exec_module(mod)
            base = path.resolve().parent
        else:
            try:
                mod = importlib.import_module(key)
            except ModuleNotFoundError as exc:
                if exc.name and key.startswith(exc.name):
                    raise InputError(
                        "plugin module not found", field="--plugin", value=key,
                        allowed="an importable module name (on PYTHONPATH or installed) or "
                        "the path of a .py file") from None
                raise
            base = Path(getattr(mod, "__file__", ".") or ".").resolve().parent
    except InputError:
        raise
    except Exception as exc:  # the plugin's own code failed
        raise InputError(f"plugin failed to import: {type(exc).__name__}: {exc}",
                         field="--plugin", value=key) from exc
    for d in getattr(mod, "SHAPE_DIRS", ()) or ():
        p = Path(d)
        p = p if p.is_absolute() else base / p
        if not p.is_dir():
            raise InputError("SHAPE_DIRS entry is not a folder", file=getattr(mod, "__file__", key),
                             field="SHAPE_DIRS", value=str(d))
        if p not in _SHAPE_DIRS:
            _SHAPE_DIRS.append(p)
    _LOADED[key] = mod
    return mod


def plugin_shape_dirs() -> list[Path]:
    """Shape folders contributed by the loaded plugins (in load order)."""
    return list(_SHAPE_DIRS)


def loaded_plugins() -> list[str]:
    """The specs of the plugins loaded so far."""
    return list(_LOADED)
