"""CSS configurations: the offset dual pyramid (O'Keefe table 2.1), the cube (table 2.2) and
user-defined sets read from TOML.

Angles: azimuth measured in the body x-y plane from +x toward +y, elevation from that plane
toward +z (both degrees in tables and TOML, radians inside).

TOML layout (degrees only in keys that say so)::

    name = "my sensors"
    fov_half_angle_deg = 90.0      # default for every sensor, in (0, 90]
    noise_sigma = 0.017            # output noise, full scale 1 (optional)
    [[sensor]]
    azimuth_deg = 0.0              # either azimuth_deg + elevation_deg ...
    elevation_deg = 45.0
    [[sensor]]
    normal = [0.0, 0.0, -1.0]      # ... or a body-frame normal (need not be unit)
    fov_half_angle_deg = 60.0      # optional per-sensor override
    scale = 1.0                    # optional true individual scale factor C_k (default 1)
    horizon_normal = [0, 0, 1]     # optional structure-horizon plane normal
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..io.tomlio import Section, load_toml
from .sensors import CSSArray, azel_to_normal

__all__ = ["DEFAULT_FOV_HALF_ANGLE_DEG", "DUAL_PYRAMID_AZEL_DEG", "CUBE_AZEL_DEG", "dual_pyramid", "cube", "from_azel_deg",
           "load_configuration", "configuration_by_name"]

# O'Keefe table 2.1 (columns: azimuth, elevation ±45°, "angled 45° from the body z axis",
# §2.2.1) with §2.2.1's offset: "the −z facing sensors are rotated by 45° about the z axis ...
# adding 45° to the azimuth angles for sensors 5 to 8 ... the configuration used in this
# research".
DUAL_PYRAMID_AZEL_DEG = np.array([
    [0.0, 45.0], [90.0, 45.0], [180.0, 45.0], [270.0, 45.0],
    [45.0, -45.0], [135.0, -45.0], [225.0, -45.0], [315.0, -45.0],
])

# O'Keefe table 2.2, cube: one sensor on each face.  Table 2.2 prints its columns in the other
# order from table 2.1 (elevation first: 0, 0, 0, 0, 90, 270 = −90), and the azimuth of
# sensor 4 as "20", a slip for 270° (the −y face): with 20° two sensors would almost coincide
# and the −y face would be blind, contradicting "one sensor on each of the six faces" (§2.2).
CUBE_AZEL_DEG = np.array([
    [0.0, 0.0], [90.0, 0.0], [180.0, 0.0], [270.0, 0.0],  # sensor 4: 270 (thesis typo "20")
    [0.0, 90.0], [0.0, -90.0],
])


# Default FOV half angle of the bundled configurations: O'Keefe §2.1.3, "the CSS 120°
# edge-to-edge field of view" (§2.2.1: the dual pyramid's sensors have "120° edge-to-edge
# fields of view").  The thesis's structure horizon of the dual pyramid (§2.2.1) is added by
# lightcurve.css.experiments.thesis_css.
DEFAULT_FOV_HALF_ANGLE_DEG = 60.0


def from_azel_deg(azel_deg, fov_half_angle_deg=90.0, *, noise_sigma=0.0, name="css",
                  **kwargs) -> CSSArray:
    """A :class:`CSSArray` from an (N, 2) table of azimuth/elevation in degrees."""
    azel = np.asarray(azel_deg, dtype=float)
    n = azel_to_normal(np.radians(azel[:, 0]), np.radians(azel[:, 1]))
    n[np.abs(n) < 1e-15] = 0.0
    return CSSArray(n, np.radians(fov_half_angle_deg), noise_sigma=noise_sigma, name=name,
                    **kwargs)


def dual_pyramid(fov_half_angle_deg=DEFAULT_FOV_HALF_ANGLE_DEG, noise_sigma=0.0, **kwargs) -> CSSArray:
    """The 8-sensor offset dual pyramid of O'Keefe table 2.1 (see ``DUAL_PYRAMID_AZEL_DEG``)."""
    return from_azel_deg(DUAL_PYRAMID_AZEL_DEG, fov_half_angle_deg, noise_sigma=noise_sigma,
                         name="dual_pyramid", **kwargs)


def cube(fov_half_angle_deg=DEFAULT_FOV_HALF_ANGLE_DEG, noise_sigma=0.0, **kwargs) -> CSSArray:
    """The 6-sensor cube of O'Keefe table 2.2 (sensor 4 azimuth 270 deg, see the comment)."""
    return from_azel_deg(CUBE_AZEL_DEG, fov_half_angle_deg, noise_sigma=noise_sigma,
                         name="cube", **kwargs)


def configuration_by_name(name: str, **kwargs) -> CSSArray:
    """'dual_pyramid', 'cube', or a path to a TOML file."""
    if name in ("dual_pyramid", "pyramid"):
        return dual_pyramid(**kwargs)
    if name == "cube":
        return cube(**kwargs)
    return load_configuration(name)


def load_configuration(path) -> CSSArray:
    """Read a CSS configuration TOML file (layout in the module docstring).

    Raises :class:`InputError` naming the file and field for zero-length normals, FOV half
    angles outside (0, 90] deg, unknown keys and missing sensors.
    """
    doc = Section(load_toml(path), file=path)
    name = doc.str("name", "user")
    fov_default = doc.float("fov_half_angle_deg", 90.0, min=0.0, max=90.0, min_open=True)
    noise = doc.float("noise_sigma", 0.0, min=0.0)
    sensors = doc.sections("sensor")
    doc.check_unknown()
    if not sensors:
        raise InputError("no sensors defined", file=path, field="sensor",
                         allowed="one or more [[sensor]] tables")
    normals, fovs, scales, horizons, names = [], [], [], [], []
    for i, s in enumerate(sensors):
        if s.has("normal"):
            if s.has("azimuth_deg") or s.has("elevation_deg"):
                raise InputError("give either 'normal' or azimuth_deg/elevation_deg, not both",
                                 file=path, field=f"sensor[{i}]")
            n = s.vector("normal", n=3)
            if np.linalg.norm(n) < 1e-12:
                raise InputError("zero-length normal", file=path, field=f"sensor[{i}].normal",
                                 value=n.tolist(), allowed="a non-zero 3-vector")
            n = n / np.linalg.norm(n)
        else:
            az = s.float("azimuth_deg", min=-360.0, max=360.0)
            el = s.float("elevation_deg", min=-90.0, max=90.0)
            n = azel_to_normal(np.radians(az), np.radians(el))
        fovs.append(np.radians(s.float("fov_half_angle_deg", fov_default, min=0.0, max=90.0,
                                       min_open=True)))
        scales.append(s.float("scale", 1.0, min=0.0, min_open=True))
        h = s.vector("horizon_normal", None, n=3)
        horizons.append(np.zeros(3) if h is None else h)
        names.append(s.str("name", f"css{i + 1}"))
        s.check_unknown()
        normals.append(n)
    return CSSArray(np.array(normals), np.array(fovs), scale_individual=np.array(scales),
                    noise_sigma=noise, horizon_normals=np.array(horizons), name=name,
                    sensor_names=tuple(names))
