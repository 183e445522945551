"""gpsdr: post-process vehicle GNSS + gyro + odometer logs with adaptive Kalman filters.

Data flow, one module each: read (``io``) -> align (``align``, which makes the
``epochs.Epochs`` every later stage reads) -> project (``geodesy``) -> filter and
smooth (``filters``: the forward passes, their RTS smoothers in ``filters.smoothing``
and the fused pass, the robust batch smoother ``filters.graph``) -> evaluate
(``evaluation``, ``qc``) -> write (``io.parquet``, ``io.export``); ``pipeline``
strings them together and ``cli`` is the thin command layer.  Imports only run down
that chain (docs/contributing.md).  Frames, units, signs and the time base are
declared once in :mod:`gpsdr_cli.conventions`.
"""

# Before any kernel module is imported: numba's cache keyed by the kernels' sources.
from .kernel_cache import configure as _configure_kernel_cache

__version__ = "0.1.0"

_configure_kernel_cache()
