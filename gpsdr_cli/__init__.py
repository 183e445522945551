"""gpsdr: post-process vehicle GNSS + gyro + odometer logs with adaptive Kalman filters.

Data flow, one module each: read (``io``) -> align (``align``) -> project
(``geodesy``) -> filter (``filters``) -> smooth (``smoothing``) -> evaluate
(``evaluation``) -> write (``io.parquet``); ``pipeline`` strings them together
and ``cli`` is the thin command layer.  Frames, units, signs and the time base
are declared once in :mod:`gpsdr_cli.conventions`.
"""

__version__ = "0.1.0"
