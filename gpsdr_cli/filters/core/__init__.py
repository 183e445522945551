"""The Kalman maths both filter families share (numba, nopython, ``cache=True``).

The current-statistical filters (ekf, aekf: :mod:`~gpsdr_cli.filters.kernels_aekf`) and
the federated filters (fkf, fafkf: :mod:`~gpsdr_cli.filters.kernels_fkf`) call these for
every operation they have in common, so each is written once:

``linalg``   Cholesky with floored pivots, its solve, the SPD test, symmetrisation
``packing``  the upper triangle of a symmetric covariance, packed row by row, and back
``update``   one guarded scalar measurement update in Joseph form (consider mask,
             optional along-track projection of the gain, a scale on R)
``gate``     the chi-square innovation gate and its one reset rule
``rts``      one Rauch-Tung-Striebel backward step

Nothing here knows a state layout: the families name their states in their own
modules (:mod:`gpsdr_cli.models.cs_model`, :mod:`~gpsdr_cli.filters.kernels_fkf`).
The equations are in docs/algorithms.md (#cycle, #rts).
"""
