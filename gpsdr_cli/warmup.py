"""Compile the filter kernels before the data arrive: the cold start.

A run after installing gpsdr (or after numba's on-disk cache was cleared)
spends about 4 s compiling the aekf kernel, against ~2 s for the whole rest of
a one-hour drive.  Nothing in that compilation depends on the drive, only on
the filter and its parameters (which options are on), so two things help:

* :func:`warm_up` compiles, or loads from numba's cache, every kernel a fuse
  with these parameters calls, by running the filter on a tiny synthetic drive
  (:func:`tiny_epochs`, 40 s, all sensors, a stop, a turn and a GNSS gap).  The
  kernels' argument types come from the parameters only, so the real run then
  finds every specialisation compiled.  ``gpsdr batch`` calls it once in the
  parent before forking its workers.
* :func:`start_background` runs :func:`warm_up` in a forked process while the
  calling process imports pandas/pyarrow and reads the logs (``gpsdr fuse``),
  and :func:`BackgroundWarmUp.wait` joins it just before the filter runs; the
  filter then loads the kernels from numba's cache.  The second core turns
  ~0.7 s of reading into time the compiler had anyway.
* While it waits, the calling process prepares to load the kernels
  (:func:`prepare_loading`, ~0.4 s) -- but only once the background process
  says a CPU is free (:func:`_signal_free`): during the two-process phase below
  both CPUs compile, and a third process on them slowed that critical path by
  as much as it saved.

Why a process and not a thread: compiling is pure Python (type inference and
lowering hold the GIL), so a thread slowed the reading down as much as it
saved (timing: docs/decisions/0015-evidence-behind-the-filter-choices.md#warmup).

Two compile processes (:func:`_warm_up_in_two`, ekf/aekf): the kernel needs every
callee compiled before its own compile; the callees fall into two independent
halves (:func:`compile_parts`), so the background process forks a helper for one
half, compiles the other, waits for the helper and compiles the kernel, which loads
the helper's functions from numba's cache.  On the one-hour drive that takes the
callees' ~45 % of the compile off the critical path, for ~0.5 s more CPU in all
(numba's own caches warm up in each process).  ``GPSDR_WARM_UP_SPLIT=0`` compiles in
one process (a comparison, or a machine whose second CPU is busy).

Safety: numba writes each cache file to a temporary name and renames it, so
two processes compiling the same function cannot leave a torn cache; a child
that fails or is killed costs nothing but the time (the caller compiles what
is missing itself).  Nothing is started when the cache already holds fresh
entries for the kernel modules, on one CPU, where ``fork`` does not exist, in
a process with other threads (fork copies only the calling one), or when the
environment sets ``GPSDR_WARM_UP=0``.

Units and conventions of the synthetic drive follow :mod:`gpsdr_cli.conventions`
(seconds, metres ENU, yaw rate counter-clockwise positive).
"""

from __future__ import annotations

import copy
import hashlib
import os
import sys
from pathlib import Path
from typing import Any

from .config import Params

#: filter name -> the modules holding its compiled kernels (smoothing only with --smooth)
KERNEL_MODULES: dict[str, tuple[str, ...]] = {
    "ekf": ("filters/kernels_aekf.py",),
    "aekf": ("filters/kernels_aekf.py",),
    "fkf": ("filters/kernels_fkf.py",),
    "fafkf": ("filters/kernels_fkf.py",),
}
SMOOTHING_MODULES: dict[str, tuple[str, ...]] = {
    "ekf": ("filters/smoothing.py",), "aekf": ("filters/smoothing.py",),
}

#: Longest wait for the background compile (s); after it the caller compiles itself.
WAIT_TIMEOUT_S = 300.0


def tiny_epochs(duration_s: float = 40.0, rate_hz: float = 100.0, gnss_hz: float = 5.0) -> Any:
    """A synthetic drive as :class:`~gpsdr_cli.epochs.Epochs`: every input a filter reads.

    Parked for 5 s, then accelerating at 1 m/s^2 to 10 m/s heading north-east,
    a 90-degree left turn at 0.2 rad/s from t = 20 s, GNSS fixes (with speed
    and course) at ``gnss_hz`` except for a 6-s gap from t = 28 s, gyro and
    odometer at every epoch.  Noise-free: it exists to exercise code paths,
    not to measure accuracy.
    """
    import numpy as np

    from .align import outage_mask
    from .epochs import Epochs

    n = int(duration_s * rate_hz) + 1
    t_s = np.arange(n) / rate_hz
    speed = np.clip(t_s - 5.0, 0.0, 10.0)  # m/s
    yaw = np.where((t_s >= 20.0) & (t_s < 20.0 + np.pi / 2 / 0.2), 0.2, 0.0)  # rad/s, CCW+
    heading = np.pi / 4 - np.concatenate(([0.0], np.cumsum(yaw[1:] / rate_hz)))  # cw from north
    dt = np.diff(t_s, prepend=t_s[0])
    e = np.cumsum(speed * np.sin(heading) * dt)
    nn = np.cumsum(speed * np.cos(heading) * dt)
    step = round(rate_hz / gnss_hz)
    has_gnss = (np.arange(n) % step == 0) & ~((t_s >= 28.0) & (t_s < 34.0))
    nan = np.full(n, np.nan)

    def at_fixes(values: np.ndarray) -> np.ndarray:
        return np.where(has_gnss, values, np.nan)

    gap_s = 1.5
    t_ns = (1_700_000_000.0 * 1e9 + t_s * 1e9).astype(np.int64)
    return Epochs(
        t_ns=t_ns, dt_s=dt,
        has_gnss=has_gnss, gnss_e=at_fixes(e), gnss_n=at_fixes(nn),
        gnss_sd_e=at_fixes(np.full(n, 1.5)), gnss_sd_n=at_fixes(np.full(n, 1.5)),
        pdop=at_fixes(np.where(t_s < 15.0, 1.8, 4.5)), gnss_speed_mps=at_fixes(speed),
        gnss_course_rad=at_fixes(np.where(speed > 0.0, heading, nan)),
        has_gyro=np.ones(n, bool), yaw_rate_radps=yaw, has_odo=np.ones(n, bool),
        odo_speed_mps=speed, gnss_outage=outage_mask(t_ns, t_ns[has_gnss], gap_s), gap_s=gap_s)


def warm_up(params: Params, *, auto_gnss_offset: bool = False) -> None:
    """Compile (or load from numba's cache) the kernels a fuse with ``params`` calls.

    ``params["filter"]["name"]`` and its smoother choose the kernels (``auto``: the graph's
    too, since the drive decides); with
    ``auto_gnss_offset`` the smoothed probe pass's kernels too.
    """
    from . import filters

    name = params["filter"]["name"]
    run = filters.get(name)
    epochs = tiny_epochs()
    from .pipeline import smoother_of

    smoother = smoother_of(params)
    smooths = {smoother != "none"}
    if auto_gnss_offset:
        smooths.add(True)
    graph = smoother in ("graph", "auto")
    if graph:
        smooths.add(True)
    from .qc import qc_enabled

    if qc_enabled(params):
        smooths.add(False)  # the forward/backward QC passes are unsmoothed
    for smooth in sorted(smooths):
        p = copy.deepcopy(params)
        p["filter"]["smooth"] = smooth
        result = run(epochs, p)
        if graph and smooth:
            from .filters.graph import smooth_graph

            smooth_graph(epochs, result, p)


def cache_is_fresh(params: Params, *, auto_gnss_offset: bool = False) -> bool:
    """Whether numba's cache already holds entries newer than each kernel module's source.

    A heuristic (numba keeps one index file per function, ``*.nbi``, next to
    the source in ``__pycache__``, or under ``NUMBA_CACHE_DIR`` when set): a false
    "fresh" only means the run compiles as it would without this module.
    """
    name = params["filter"]["name"]
    mods = list(KERNEL_MODULES.get(name, ()))
    from .pipeline import smoother_of

    smoother = smoother_of(params)
    if smoother != "none" or auto_gnss_offset:
        mods += SMOOTHING_MODULES.get(name, ())
    if smoother in ("graph", "auto"):
        mods.append("filters/graph_kernels.py")
    root = Path(__file__).resolve().parent
    user_dir = os.environ.get("NUMBA_CACHE_DIR")
    for rel in mods:
        src = root / rel
        try:
            src_mtime = src.stat().st_mtime
        except OSError:
            return False
        if user_dir:  # numba's _UserProvidedCacheLocator: <dir>/<folder name>_<sha1 of folder>
            folder = os.path.dirname(os.path.abspath(src))
            sub = f"{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}"
            dirs = [Path(user_dir) / sub]
        else:
            dirs = [src.parent / "__pycache__"]
        newest = max((p.stat().st_mtime for d in dirs if d.is_dir()
                      for p in d.glob(f"{src.stem}.*.nbi")), default=-1.0)
        if newest < src_mtime:
            return False
    return True


def fork_is_safe() -> bool:
    """Whether this process may ``fork``: the start method exists and no other thread runs.

    fork copies only the calling thread: with other threads alive (a progress bar,
    a dask client) a lock one of them holds would stay locked in the child forever.
    """
    import multiprocessing as mp
    import threading

    return "fork" in mp.get_all_start_methods() and threading.active_count() == 1


def flush_std_streams() -> None:
    """Empty stdout/stderr before a fork: a child flushes its copy of the buffers at exit."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass


def prepare_loading(name: str) -> None:
    """The caller's own start-up of the kernels that does not need the cache: import the
    filter's module and initialise numba's CPU target.

    The first kernel call in a process refreshes numba's target context (its extra
    registries, numpy support, the BLAS check: ~0.45 s), cache hit or not;
    :meth:`BackgroundWarmUp.wait` does it while the compile runs, not after.
    """
    from . import filters

    filters.get(name)
    refresh_cpu_target()


def refresh_cpu_target() -> None:
    """Initialise numba's CPU target (its extra registries, numpy support) once per process.

    numba's BLAS probe (``numba.np.linalg.ensure_blas``, run when the target loads its
    numpy registry) imports ``scipy.linalg.cython_blas``, and through it the whole
    ``scipy.linalg`` package (~0.15-0.35 s and ~12 MB on the one-hour drive: scipy's
    array-API layer imports numpy.f2py and unittest), although only the extension module
    itself is probed.  So the extension module alone is loaded for the probe, under its
    own name, and taken out of ``sys.modules`` again afterwards: a later ``import
    scipy.linalg`` (the graph smoother) imports the package as usual and finds the same
    module object (Cython keeps one instance per process).  Nothing changes where scipy
    is missing or ``scipy.linalg`` is already imported.
    """
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.registry import cpu_target

    seeded = _seed_cython_blas()
    try:
        # under numba's compiler lock: :class:`Preload` runs this in a thread while the main
        # thread may compile a kernel not in the cache (align's, for out-of-order stamps),
        # and a compile that typed against a half-refreshed target failed with "Unknown
        # attribute 'max' of type array(int64, 1d, C)"
        with global_compiler_lock:
            cpu_target.target_context.refresh()
    finally:
        if seeded:
            package = sys.modules.get("scipy.linalg")
            if package is None:
                sys.modules.pop(_CYTHON_BLAS, None)
            elif not hasattr(package, "cython_blas"):  # imported meanwhile: as an import would
                package.cython_blas = sys.modules[_CYTHON_BLAS]


_CYTHON_BLAS = "scipy.linalg.cython_blas"


def _seed_cython_blas() -> bool:
    """Put ``scipy.linalg.cython_blas`` in ``sys.modules`` without ``scipy.linalg``'s
    ``__init__``; True if this call did (see :func:`refresh_cpu_target`)."""
    if _CYTHON_BLAS in sys.modules or "scipy.linalg" in sys.modules:
        return False
    import importlib.machinery
    import importlib.util

    try:
        import scipy
    except ImportError:
        return False
    folder = os.path.join(os.path.dirname(scipy.__file__), "linalg")
    found = importlib.machinery.PathFinder.find_spec("cython_blas", [folder])
    if found is None or not isinstance(found.loader, importlib.machinery.ExtensionFileLoader):
        return False
    spec = importlib.util.spec_from_file_location(_CYTHON_BLAS, found.origin)
    if spec is None or spec.loader is None:
        return False
    try:
        module = importlib.util.module_from_spec(spec)
        sys.modules[_CYTHON_BLAS] = module
        spec.loader.exec_module(module)
    except Exception:  # numba's own probe then imports the package as before
        sys.modules.pop(_CYTHON_BLAS, None)
        return False
    return True


class BackgroundWarmUp:
    """A forked process running :func:`warm_up`; :meth:`wait` joins it.

    ``free_fd``: the read end of a pipe on which the process writes a byte when it
    leaves a CPU free (:func:`_signal_free`), or None.
    """

    def __init__(self, proc: Any, name: str = "", free_fd: int | None = None) -> None:
        self.proc = proc
        self.name = name
        self.free_fd = free_fd

    def _close_free_fd(self) -> None:
        if self.free_fd is not None:
            os.close(self.free_fd)
            self.free_fd = None

    def wait(self, timeout_s: float = WAIT_TIMEOUT_S) -> bool:
        """Block until the compile finished; False if it failed or timed out (harmless).

        Meanwhile, once the process signals a free CPU (or ends), this process prepares
        to load the kernels (:func:`prepare_loading`).
        """
        import select

        if self.proc is None:
            return False
        if self.free_fd is not None:
            select.select([self.free_fd], [], [], timeout_s)  # a byte, or EOF: it ended
            self._close_free_fd()
        if self.name:
            prepare_loading(self.name)
        self.proc.join(timeout_s)
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(5.0)
        ok = self.proc.exitcode == 0
        self.proc = None
        return ok

    def cancel(self) -> None:
        """Stop the compile if it still runs (the caller failed before it needed the kernels)."""
        self._close_free_fd()
        if self.proc is not None and self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(5.0)
        self.proc = None


class Preload:
    """:func:`prepare_loading` in a thread of this process while it reads the logs (warm
    cache: nothing to compile); :meth:`wait` joins it before the first kernel call.

    Importing numba and refreshing its target is ~0.5 s of pure Python, but much of
    the reading (pyarrow's CSV parse, numpy's sorts and casts on whole columns) runs
    without the GIL, so on a second CPU part of the start-up hides behind the reading.
    Any failure in the thread is ignored: :meth:`wait` then does the same work itself.
    """

    def __init__(self, name: str) -> None:
        import threading

        self.name = name
        self._thread: Any = threading.Thread(target=self._run, name="gpsdr-preload",
                                             daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            prepare_loading(self.name)
        except BaseException:  # noqa: BLE001 - the caller repeats it and sees the error
            pass

    def wait(self, timeout_s: float = WAIT_TIMEOUT_S) -> bool:
        """Join the thread, then make sure the filter and numba's target are ready."""
        self.cancel(timeout_s)
        prepare_loading(self.name)
        return True

    def cancel(self, timeout_s: float = WAIT_TIMEOUT_S) -> None:
        """Wait for the thread (imports cannot be interrupted; it ends on its own)."""
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None


def _second_cpu() -> bool:
    """Whether work beside the main thread may run: ``GPSDR_WARM_UP`` is not 0 and this
    process may use a second CPU."""
    if os.environ.get("GPSDR_WARM_UP", "1") == "0":
        return False
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:
        cpus = os.cpu_count() or 1
    return cpus >= 2


def start_preload(params: Params) -> Preload | None:
    """A :class:`Preload` for ``params``' filter when a second CPU can run it, else None.

    ``GPSDR_WARM_UP=0`` turns it off with the background compile."""
    if not _second_cpu():
        return None
    return Preload(str(params["filter"]["name"]))


def compile_parts(params: Params) -> tuple[Any, ...]:
    """Parts of the filter's kernel compile (callables) for :func:`_warm_up_in_two`, or ().

    ekf/aekf: :func:`gpsdr_cli.filters.aekf.compile_parts` (five parts, run as
    :func:`_warm_up_in_two` says).  The kernel itself compiles after them, in :func:`warm_up`.
    """
    name = params["filter"]["name"]
    if name not in ("ekf", "aekf"):
        return ()
    from .filters.aekf import compile_parts as cs_parts

    return cs_parts(params, adaptive=name == "aekf")


def _join(pid: int, timeout_s: float) -> None:
    """Wait for the forked process ``pid`` at most ``timeout_s``; then kill it."""
    import signal
    import time

    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        done, _ = os.waitpid(pid, os.WNOHANG)
        if done:
            return
        time.sleep(0.01)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)


def _signal_free(fd: int | None) -> None:
    """Tell the waiting caller that a CPU is free now (one byte on ``fd``; then closed)."""
    if fd is None:
        return
    try:
        os.write(fd, b"1")
    except OSError:  # the caller has gone: nobody to tell
        pass
    os.close(fd)


def _warm_up_in_two(params: Params, auto_gnss_offset: bool, free_fd: int | None = None) -> None:
    """:func:`warm_up` with the kernel's callees compiled in two processes.

    On two CPUs the parent reading the logs, this process and a forked helper share
    them.  With the five parts of :func:`compile_parts`: [0] here, before the fork;
    then the helper runs [1], waits until this process has run [3] (the end of a pipe
    this process closes then, or dies with) and runs [2], while this process runs [3] and [4],
    waits for the helper and compiles the kernel, which loads the helper's functions
    from numba's cache.  The helper failing or being slow costs only time: the kernel
    compiles what it misses.  A plain ``os.fork``: this process is a daemonic
    multiprocessing child, which may not start multiprocessing children of its own.
    When the kernel's compile starts (one process, a CPU free) it writes to ``free_fd``
    (:func:`_signal_free`; at once without a helper).
    """
    import select
    import signal

    parts = compile_parts(params)
    if not parts:  # fkf/fafkf: one process
        _signal_free(free_fd)
        warm_up(params, auto_gnss_offset=auto_gnss_offset)
        return
    parts[0]()  # what both halves need, once; numba's own start-up (~0.5 s) too
    ready_r, ready_w = os.pipe()
    try:
        pid = os.fork()
    except OSError:  # no second process (a limit): everything here
        os.close(ready_r)
        os.close(ready_w)
        _signal_free(free_fd)
        warm_up(params, auto_gnss_offset=auto_gnss_offset)
        return
    if pid == 0:  # the helper, out without the parent's exit handlers
        code = 1
        try:
            os.close(ready_w)
            if free_fd is not None:
                os.close(free_fd)  # only this process's byte or end may wake the caller
            parts[1]()
            select.select([ready_r], [], [], WAIT_TIMEOUT_S)
            parts[2]()
            code = 0
        finally:
            os._exit(code)
    os.close(ready_r)

    def stop(signum: int, frame: Any) -> None:  # cancelled by the parent: the helper too
        os.kill(pid, signal.SIGKILL)
        os._exit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        try:
            parts[3]()
        finally:
            os.close(ready_w)  # the end of the pipe wakes the helper, [3] done or failed
        parts[4]()
    finally:
        _join(pid, WAIT_TIMEOUT_S)
        signal.signal(signal.SIGTERM, previous)
    _signal_free(free_fd)  # the kernel compiles in this process alone
    warm_up(params, auto_gnss_offset=auto_gnss_offset)


def _child(params: Params, auto_gnss_offset: bool, fds: tuple[int, int] | None = None) -> None:
    # no output from here: the parent owns stdout (it may be a pipe carrying the track)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115 - lives as long as the process
    # a short-lived compiler: the collector's passes over numba's IR cost more than the
    # cycles they free (the process and its memory end with the compile)
    import gc

    gc.disable()
    free_fd = None
    if fds is not None:
        os.close(fds[0])  # the caller's end
        free_fd = fds[1]
    if os.environ.get("GPSDR_WARM_UP_SPLIT", "1") == "0":
        _signal_free(free_fd)
        warm_up(params, auto_gnss_offset=auto_gnss_offset)
    else:
        _warm_up_in_two(params, auto_gnss_offset, free_fd)


def start_background(params: Params, *, auto_gnss_offset: bool = False) -> BackgroundWarmUp | None:
    """Start :func:`warm_up` in a forked process when it can help, else None.

    It can help when numba's cache is not fresh for this filter, there is a
    second CPU to run it on, and ``fork`` exists (the child must not re-import
    and re-parse the command line).
    """
    # the cache first: a warm run does not import multiprocessing for fork_is_safe
    if not _second_cpu() or cache_is_fresh(params, auto_gnss_offset=auto_gnss_offset) \
            or not fork_is_safe():
        return None
    import multiprocessing as mp

    flush_std_streams()
    fds = os.pipe()
    proc = mp.get_context("fork").Process(target=_child, args=(params, auto_gnss_offset, fds),
                                          name="gpsdr-warm-up", daemon=True)
    try:
        proc.start()
    finally:
        os.close(fds[1])  # the child's end: its byte, or its exit, wakes wait()
    return BackgroundWarmUp(proc, params["filter"]["name"], fds[0])
