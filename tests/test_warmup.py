"""The kernel warm-up (gpsdr_cli.warmup): it compiles what a real run calls, and a
background compile leaves a cache the run then loads instead of compiling.

Each check runs in a fresh interpreter: in this process earlier tests have
compiled the kernels already, so a missing specialisation could not show.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]

#: Counts, in a fresh interpreter, the specialisations gpsdr's own compiled functions gain
#: in a real fuse after warm_up: it must be none (the simulator's kernel aside).
COVERAGE = textwrap.dedent("""
    import copy, sys
    from gpsdr_cli.config import defaults
    from gpsdr_cli import warmup
    name, smooth, auto = sys.argv[1], sys.argv[2] == "1", sys.argv[3] == "1"
    p = defaults(); p["filter"]["name"] = name; p["filter"]["smooth"] = smooth
    warmup.warm_up(p, auto_gnss_offset=auto)
    from numba.core.registry import CPUDispatcher
    def sigs():
        return {f"{m}.{k}": len(v.signatures) for m, mod in list(sys.modules.items())
                if m.startswith("gpsdr_cli") and m != "gpsdr_cli.simulate"
                for k, v in vars(mod).items() if isinstance(v, CPUDispatcher)}
    before = sigs()
    from gpsdr_cli.simulate import simulate_drive
    from gpsdr_cli.pipeline import fuse
    for scenario in ("urban_canyon", "tunnels"):
        sim = simulate_drive(scenario, seed=3, duration_s=150)
        fuse(sim.drive, copy.deepcopy(p), None, auto_gnss_offset=auto)
    after = sigs()
    new = {k: v - before.get(k, 0) for k, v in after.items() if v != before.get(k, 0)}
    print("NEW", new)
""")


@pytest.mark.parametrize(("name", "smooth", "auto"), [
    ("aekf", True, True), ("ekf", False, False), ("fkf", True, False), ("fafkf", False, True)])
def test_warm_up_compiles_every_kernel_a_real_fuse_calls(name: str, smooth: bool,
                                                          auto: bool) -> None:
    res = subprocess.run([sys.executable, "-c", COVERAGE, name, str(int(smooth)), str(int(auto))],
                         capture_output=True, text=True, cwd=REPO, check=False, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "NEW {}" in res.stdout, res.stdout  # a kernel compiled after the warm-up: it missed it


#: Runs, in a fresh interpreter with an empty numba cache, the ekf/aekf kernel's compile
#: parts (warmup.compile_parts) and then warm_up: the kernel must find every callee the
#: parts compiled with its own argument types (else numba compiles it again, the cold
#: start's time lost).
PARTS = textwrap.dedent("""
    import json, sys
    from numba.core import event
    from gpsdr_cli.config import defaults
    from gpsdr_cli import warmup
    p = defaults()
    p["filter"]["name"] = sys.argv[1]
    p["filter"]["smoother"] = "none"  # the filter's kernel alone (the graph's compile after it)
    for sec, kv in json.loads(sys.argv[2]).items():
        p[sec].update(kv)
    parts = warmup.compile_parts(p)
    for part in parts:
        part()
    compiled = []
    class Listener(event.Listener):
        def on_start(self, ev):
            pass
        def on_end(self, ev):
            compiled.append(ev.data["dispatcher"].py_func.__name__)
    event.register("numba:compile", Listener())
    warmup.warm_up(p)
    print("PARTS", len(parts), "COMPILED", sorted(compiled))
""")


@pytest.mark.parametrize(("name", "options"), [
    ("aekf", {}),
    ("ekf", {"aekf": {"gnss_err_states": False, "turn_propagation": False},
             "adaptive": {"sage_husa": True, "innovation_factor": True}}),
])
def test_compile_parts_leave_only_the_kernel_to_compile(tmp_path: Path, name: str,
                                                        options: dict) -> None:
    import json

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    res = subprocess.run([sys.executable, "-c", PARTS, name, json.dumps(options)], env=env,
                         capture_output=True, text=True, cwd=REPO, check=False, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "PARTS 5 COMPILED ['cs_filter_kernel']" in res.stdout, res.stdout


#: The two-process warm-up with a helper that fails at once: the kernel still compiles
#: (what the helper should have compiled with it) and the cache ends up fresh.
HELPER_FAILS = textwrap.dedent("""
    from gpsdr_cli import warmup
    from gpsdr_cli.config import defaults
    own = warmup.compile_parts
    def failing(params):
        parts = list(own(params))
        def boom():
            raise RuntimeError("helper failed")
        parts[1] = boom
        return tuple(parts)
    warmup.compile_parts = failing
    p = defaults()
    print("FRESH BEFORE", warmup.cache_is_fresh(p))
    warmup._warm_up_in_two(p, False)
    print("FRESH AFTER", warmup.cache_is_fresh(p))
""")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the helper is forked")
def test_two_process_warm_up_survives_a_failing_helper(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    res = subprocess.run([sys.executable, "-c", HELPER_FAILS], env=env, capture_output=True,
                         text=True, cwd=REPO, check=False, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "FRESH BEFORE False" in res.stdout and "FRESH AFTER True" in res.stdout, res.stdout


def test_tiny_epochs_exercise_every_input() -> None:
    from gpsdr_cli.warmup import tiny_epochs

    ep = tiny_epochs()
    assert len(ep) == 4001
    assert 150 < ep.n_gnss < 200  # 5 Hz for 40 s, minus the 6-s gap
    assert ep.gnss_outage.any() and not ep.gnss_outage[ep.has_gnss].any()
    assert (ep.odo_speed_mps == 0.0).sum() >= 500  # parked for 5 s: the standstill path
    assert np.abs(ep.yaw_rate_radps).max() == pytest.approx(0.2)  # the turn
    assert np.isfinite(ep.gnss_course_rad[ep.has_gnss & (ep.gnss_speed_mps > 0)]).all()


@pytest.mark.skipif(not hasattr(os, "fork") or len(os.sched_getaffinity(0)) < 2,
                    reason="the background compile needs fork and a second CPU")
def test_cold_fuse_with_a_background_compile_gives_the_same_track(tmp_path: Path) -> None:
    """An empty numba cache: `gpsdr fuse -o - --format csv` forks the compiler, which must
    not write to the pipe, leaves a fresh cache, and the track equals a warm run's."""
    from gpsdr_cli.simulate import simulate_drive, write_drive

    write_drive(simulate_drive("urban_canyon", seed=5, duration_s=120), tmp_path / "d",
                mcap=False)
    d = tmp_path / "d"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("GPSDR_WARM_UP", None)
    cmd = [sys.executable, "-c", "from gpsdr_cli.cli.main import main; main()",
           "fuse", "--gps", str(d / "gps.nmea"),
           "--gyro", str(d / "gyro.csv"), "--odo", str(d / "odo.csv"), "-o", "-",
           "--format", "csv", "-q"]
    probe = textwrap.dedent("""
        from gpsdr_cli.config import defaults
        from gpsdr_cli.warmup import cache_is_fresh
        print(cache_is_fresh(defaults()))
    """)

    def fresh() -> str:
        return subprocess.run([sys.executable, "-c", probe], env=env, cwd=REPO, text=True,
                              capture_output=True, check=True).stdout.strip()

    assert fresh() == "False"
    cold = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, timeout=600, check=False)
    assert cold.returncode == 0, cold.stderr[-2000:]
    assert fresh() == "True"  # the child (or the parent) filled the cache
    warm = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, timeout=600, check=False)
    assert warm.returncode == 0, warm.stderr[-2000:]
    a = pd.read_csv(pd.io.common.BytesIO(cold.stdout))
    b = pd.read_csv(pd.io.common.BytesIO(warm.stdout))
    assert len(a) > 10_000
    pd.testing.assert_frame_equal(a, b)


#: The "CPU free" signal of the two-process warm-up: written once every part has run (the
#: helper's too), before the kernel compiles; at once when there are no parts (fkf).
FREE_SIGNAL = textwrap.dedent("""
    import os, sys, time
    from gpsdr_cli import warmup
    from gpsdr_cli.config import defaults
    log = sys.argv[1]
    def mark(tag):
        with open(log, "a") as f:
            f.write(tag)
    def part(tag, delay=0.0):
        def run():
            time.sleep(delay)
            mark(tag)
        return run
    n_parts = int(sys.argv[2])
    warmup.compile_parts = lambda params: tuple(
        part(str(i), 0.5 if i == 1 else 0.0) for i in range(n_parts))
    warmup.warm_up = lambda params, auto_gnss_offset=False: mark("K")
    own_signal = warmup._signal_free
    def signal(fd):
        mark("S")
        own_signal(fd)
    warmup._signal_free = signal
    r, w = os.pipe()
    warmup._warm_up_in_two(defaults(), False, w)
    print("PIPE", os.read(r, 8))
""")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the helper is forked")
@pytest.mark.parametrize("n_parts", [5, 0])
def test_warm_up_signals_a_free_cpu_before_the_kernel_compiles(tmp_path: Path,
                                                                n_parts: int) -> None:
    log = tmp_path / "order.txt"
    res = subprocess.run([sys.executable, "-c", FREE_SIGNAL, str(log), str(n_parts)],
                         capture_output=True, text=True, cwd=REPO, check=False, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "PIPE b'1'" in res.stdout, res.stdout
    order = log.read_text()
    if n_parts:
        # part 0 first; the helper's slow part 1 (and 2) before the signal; the kernel last
        assert order[0] == "0" and sorted(order[1:5]) == list("1234"), order
        assert order[5:] == "SK", order
    else:
        assert order == "SK", order


#: In a fresh interpreter: the target refresh that a warm fuse does before its first kernel.
BLAS_PROBE = textwrap.dedent("""
    import sys
    import numpy as np
    from gpsdr_cli.warmup import refresh_cpu_target
    refresh_cpu_target()
    from numba.np import arraymath
    print("have_blas", arraymath._HAVE_BLAS)
    print("package_imported", "scipy.linalg" in sys.modules)
    print("left_in_modules", "scipy.linalg.cython_blas" in sys.modules)
    import numba
    import scipy.linalg
    print("attribute", scipy.linalg.cython_blas.__name__)

    @numba.njit
    def solve(a, b):  # BLAS/LAPACK through numba after the lean probe
        return np.linalg.solve(a, b) + np.dot(a, b)

    a = np.array([[4.0, 1.0], [1.0, 3.0]])
    b = np.array([1.0, 2.0])
    print("numba_linalg", bool(np.allclose(solve(a, b), scipy.linalg.solve(a, b) + a @ b)))
""")


def test_target_refresh_probes_blas_without_the_scipy_linalg_package() -> None:
    """numba's BLAS probe finds BLAS (so its typing is as before), scipy.linalg's package
    is not imported for it, and a later import of the package and numba's linear algebra
    work as usual."""
    out = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True,
                         check=True, env={**os.environ, "PYTHONPATH": str(REPO)}).stdout
    got = dict(line.split(" ", 1) for line in out.splitlines())
    assert got == {"have_blas": "True", "package_imported": "False", "left_in_modules": "False",
                   "attribute": "scipy.linalg.cython_blas", "numba_linalg": "True"}


def test_preload_is_joined_before_the_filter_runs() -> None:
    """The warm path's start-up thread has ended when ``wait`` returns, and the filter is
    registered; a second ``wait`` (the auto-offset probes call it again) is harmless."""
    import threading

    from gpsdr_cli import filters, warmup
    from gpsdr_cli.config import defaults

    pre = warmup.start_preload(defaults())
    if pre is None:
        pytest.skip("one CPU: no preload thread")
    assert pre.wait() and pre.wait()
    assert not any(t.name == "gpsdr-preload" for t in threading.enumerate())
    assert "aekf" in filters._REGISTRY



def test_the_preload_thread_refreshes_numba_under_its_compiler_lock(monkeypatch) -> None:
    """The preload thread refreshes numba's target under numba's compiler lock, so that a
    compile in the main thread meanwhile (align's kernel, on a log with out-of-order stamps,
    is not in the cache) waits for it: typed against a half-refreshed target it failed with
    "Unknown attribute 'max' of type array(int64, 1d, C)" on a real NMEA log."""
    import threading

    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.registry import cpu_target

    from gpsdr_cli import warmup

    held: list[bool] = []
    monkeypatch.setattr(cpu_target.target_context, "refresh",
                        lambda: held.append(global_compiler_lock.is_locked()))
    thread = threading.Thread(target=warmup.refresh_cpu_target)
    thread.start()
    thread.join(30.0)
    assert held == [True]
