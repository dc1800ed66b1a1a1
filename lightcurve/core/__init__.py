"""The shared numerical core: numba kernels on plain floats and float64 arrays, one place per
equation, used by the lightcurve filters, the particle filter, the truth models and the
coarse-sun-sensor estimators alike (DESIGN.md, "Estimation core — one core, two sensors").

Modules (each kernel's docstring names its equation and source):

* :mod:`.constants` — physical constants (au, μ⊕, Earth rate, solar magnitude, …);
* :mod:`.rotations` — quaternion, DCM, rotation vector, GRP, MRP (+ shadow set), Euler 3-2-1;
* :mod:`.dynamics` — Euler's equations with torques and momentum wheels, the one RK4 step, the
  exact constant-rate step, error dynamics Φ and Q_d;
* :mod:`.kalman` — checked Cholesky / inverse, Joseph update (vector and scalar fast path),
  Schmidt consider update;
* :mod:`.sigma_points` — scaled unscented weights and sigma points;
* :mod:`.photometry` — BRDFs (one Cook–Torrance with its derivatives), facet flux and its
  analytic partials;
* :mod:`.particles` — particle log weights (log-sum-exp), ESS, tempering, systematic and
  multinomial resampling, Table 7.9 roughening, the Liu–West kernel, counter-based normals.

Nothing here validates its inputs or allocates Python objects: the object layers
(:mod:`lightcurve.rotations`, :mod:`lightcurve.dynamics`, :mod:`lightcurve.estimation`,
:mod:`lightcurve.photometry`, :mod:`lightcurve.filters`, :mod:`lightcurve.css`) do that and call
these kernels.
"""
