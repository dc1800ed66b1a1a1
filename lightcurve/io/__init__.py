"""File input/output: atomic writes, TOML validation, HDF5 lightcurves, CSV recordings."""
