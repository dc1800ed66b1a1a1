"""A first session with lightcurve in Python: simulate, invert, tabulate, plot.

Run it from anywhere (``python docs/example.py [OUTPUT_FOLDER]``, default ``example-out``);
``tests/docs/test_docs_example.py`` runs it end to end, so it stays working. In a notebook, run
the same lines cell by cell: the objects display themselves as small tables.
"""

import sys
from pathlib import Path

import lightcurve

out = Path(sys.argv[1] if len(sys.argv) > 1 else "example-out")
out.mkdir(parents=True, exist_ok=True)

# 1. Simulate the bundled default scenario: a 1U CubeSat spinning at 4.2 deg/s on a real, sunlit
#    pass over Socorro, NM (pipelines/default.toml). A Lightcurve prints one line, not arrays.
lc = lightcurve.simulate("default")
print(lc)

# 2. Estimate the attitude with the UKF, started 3 deg / 0.02 deg/s (1 sigma) off the truth.
est = lightcurve.invert(lc, method="ukf", seed=1, sigma_theta_deg=3.0, sigma_omega_deg_s=0.02)
print(est)

# 3. Tables (pandas, `pip install "lightcurve[pandas]"`): one row per epoch, indexed by UTC.
curve_table = lc.to_pandas()
estimate_table = est.to_pandas()
print(curve_table[["mag", "mag_sigma", "elevation_deg", "phase_angle_deg"]].describe().round(2))
final = estimate_table.iloc[-1]
print(f"final spin axis: RA {final.spin_ra_deg:.1f} deg, Dec {final.spin_dec_deg:.1f} deg, "
      f"rate {final.spin_rate_deg_s:.3f} deg/s; attitude error {abs(final.att_error_x_deg):.2f}, "
      f"{abs(final.att_error_y_deg):.2f}, {abs(final.att_error_z_deg):.2f} deg (x, y, z)")
estimate_table.to_csv(out / "estimate.csv")

# 4. Figures: the lightcurve and the analyst view of the estimate (attitude, rates, spin axis,
#    fitted lightcurve with the NIS band, errors against the truth).
lc.plot(out / "lightcurve.png", title="CubeSat pass over Socorro")
est.plot(out / "estimate.png", curve=lc)

# 5. Files: the same objects round-trip through HDF5 (docs/formats.md).
lc.write(out / "pass.h5")
est.write(out / "pass.ukf.h5")
print("wrote", ", ".join(sorted(p.name for p in out.iterdir())))
