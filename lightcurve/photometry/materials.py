"""Surface materials: a BRDF name plus its validated parameters.

TOML form (inside a shape file)::

    [materials.gold_foil]
    brdf = "cook_torrance"     # any registered BRDF (see `available_brdfs()`) or "tabulated"
    xi = 0.2                   # parameters of that BRDF, validated against its ranges
    a = 0.6
    m = 0.1

    [materials.chassis_measured]
    brdf = "tabulated"
    table = "chassis_brdf.csv" # path relative to the TOML file; see .tabulated for the format
    scale = 1.0
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from .brdf import BRDF, get_brdf
from .tabulated import TabulatedBRDF

__all__ = ["Material", "material_from_section"]

_TABLE_CACHE: dict = {}


@dataclass(frozen=True)
class Material:
    """A reflecting surface.

    Attributes
    ----------
    name : str
        Material name (key in the shape file).
    brdf : BRDF
        The reflectance model instance (from the registry, or a :class:`TabulatedBRDF`).
    params : dict
        Validated parameter values (name -> float), in the BRDF's units (dimensionless).
    """

    name: str
    brdf: BRDF
    params: dict = field(default_factory=dict)

    @property
    def brdf_name(self) -> str:
        """Registry name of the BRDF (``tabulated:<file>`` for tables)."""
        return self.brdf.name

    @classmethod
    def create(cls, name: str, brdf: str | BRDF, *, file=None, field=None, **params) -> "Material":
        """Validated constructor: looks ``brdf`` up by name and checks ``params``' ranges."""
        model = brdf if isinstance(brdf, BRDF) else get_brdf(brdf, file=file, field=f"{field}.brdf"
                                                             if field else "brdf")
        return cls(name, model, model.resolve_params(params, file=file, field=field))

    def with_params(self, **changes) -> "Material":
        """Copy with some parameters replaced (validated)."""
        p = dict(self.params)
        p.update(changes)
        return Material(self.name, self.brdf, self.brdf.resolve_params(p, field=f"materials.{self.name}"))


def material_from_section(sec, name: str, base_dir=None) -> Material:
    """Build a :class:`Material` from a :class:`~lightcurve.io.tomlio.Section`.

    ``brdf = "tabulated"`` requires ``table`` (path relative to ``base_dir``).
    """
    kind = sec.str("brdf")
    params = {k: v for k, v in sec.data.items() if k not in ("brdf", "table", "description")}
    sec.raw("description", None)
    if kind == "tabulated":
        table = sec.str("table")
        path = Path(table)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        if not path.exists():  # anything else (FIFO, device): refused by the table reader
            raise InputError("BRDF table not found", file=sec.file, field=f"{sec.name}.table",
                             value=str(path))
        key = str(path.resolve())
        if key not in _TABLE_CACHE:
            _TABLE_CACHE[key] = TabulatedBRDF.from_csv(path)
        model = _TABLE_CACHE[key]
    else:
        if sec.has("table"):
            raise InputError("'table' is only allowed with brdf = \"tabulated\"", file=sec.file,
                             field=f"{sec.name}.table")
        model = get_brdf(kind, file=sec.file, field=f"{sec.name}.brdf")
    return Material(name, model, model.resolve_params(params, file=sec.file, field=sec.name))
