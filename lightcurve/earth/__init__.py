"""The Earth as seen from a spacecraft: the albedo map (CERES / TOMS grids and the built-in
zonal model), the irradiance of its cells (O'Keefe 2015 eq. 2.15-2.18) and the Earth rotation
angle that turns inertial vectors into the map's Earth-fixed axes. Shared by the coarse-sun-
sensor models (:mod:`lightcurve.css`) and the physics effects on lightcurves
(:mod:`lightcurve.physics`, Earthshine).
"""

from .albedo import (AlbedoGrid, AlbedoMap, albedo_cells_in_view, albedo_cells_nb,
                     builtin_albedo_map, earth_rotation_angle, load_albedo_map, zonal_albedo)

__all__ = ["AlbedoGrid", "AlbedoMap", "albedo_cells_in_view", "albedo_cells_nb",
           "builtin_albedo_map", "earth_rotation_angle", "load_albedo_map", "zonal_albedo"]
