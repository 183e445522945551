"""numba's cache folder is keyed by every kernel-related source (gpsdr_cli.kernel_cache)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from gpsdr_cli import kernel_cache
from gpsdr_cli.kernel_cache import ENV_CACHE_DIR, ENV_MARKER, configure, source_key

REPO = Path(__file__).resolve().parents[1]


def _package(root: Path) -> Path:
    """A package laid out like gpsdr_cli: a kernel calling into models/, and bystanders."""
    pkg = root / "pkg"
    for rel, text in {
        "filters/kernels.py": "from numba import njit\nfrom ..models.model import phi\n",
        "models/model.py": "def phi(dt):\n    return 1.0 + dt\n",
        "conventions.py": "STEP = 1\n",
        "align.py": "import numba\n",
        "cli/main.py": "import click  # no kernel here\n",
        "geodesy.py": "# speaks of numba in a comment only\n",
    }.items():
        path = pkg / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return pkg


def test_an_edit_of_a_callee_changes_the_key(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    key = source_key(pkg)
    assert len(key) == 16 and int(key, 16) >= 0
    assert source_key(pkg) == key  # deterministic
    (pkg / "models/model.py").write_text("def phi(dt):\n    return 1.0 + 2.0 * dt\n")
    edited = source_key(pkg)
    assert edited != key  # the kernel in filters/ must not be loaded stale
    for rel in ("conventions.py", "align.py", "filters/kernels.py"):
        before = source_key(pkg)
        (pkg / rel).write_text((pkg / rel).read_text() + "# edited\n")
        assert source_key(pkg) != before, rel


def test_modules_without_kernels_leave_the_key_alone(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    key = source_key(pkg)
    (pkg / "cli/main.py").write_text("import click\nX = 2\n")
    (pkg / "geodesy.py").write_text("# numba, numba\nY = 3\n")
    assert source_key(pkg) == key


def test_configure_keys_a_given_root_once_and_children_keep_it(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    env = {ENV_CACHE_DIR: str(tmp_path / "root")}
    target = configure(env, package_dir=pkg)
    assert target == tmp_path / "root" / f"gpsdr-{source_key(pkg)}"
    assert target.is_dir() and env[ENV_CACHE_DIR] == str(target)
    child = dict(env)  # a child process inherits both variables: no second level
    assert configure(child, package_dir=pkg) == target
    (pkg / "models/model.py").write_text("def phi(dt):\n    return dt\n")
    moved = configure(child, package_dir=pkg)  # a child running edited sources
    assert moved is not None and moved.parent == tmp_path / "root" and moved != target


def test_configure_disabled_or_unwritable_leaves_numba_alone(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    env = {"GPSDR_KERNEL_CACHE_KEY": "0"}
    assert configure(env, package_dir=pkg) is None and ENV_CACHE_DIR not in env
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    env = {ENV_CACHE_DIR: str(blocker)}
    assert configure(env, package_dir=pkg) is None
    assert env == {ENV_CACHE_DIR: str(blocker)}


def test_old_keyed_folders_are_pruned(tmp_path: Path) -> None:
    pkg = _package(tmp_path)
    root = tmp_path / "root"
    for i in range(12):
        old = root / f"gpsdr-{i:016x}"
        old.mkdir(parents=True)
        os.utime(old, (1_000_000 + i, 1_000_000 + i))
    (root / "someone-else").mkdir()
    target = configure({ENV_CACHE_DIR: str(root)}, package_dir=pkg)
    kept = sorted(p.name for p in root.iterdir())
    assert target is not None and target.name in kept and "someone-else" in kept
    assert len([k for k in kept if k.startswith("gpsdr-")]) == kernel_cache.KEEP_FOLDERS
    assert "gpsdr-000000000000000b" in kept and "gpsdr-0000000000000000" not in kept


def test_the_package_import_points_numba_at_the_keyed_folder(tmp_path: Path) -> None:
    code = ("import os, gpsdr_cli, numba\n"
            "from gpsdr_cli.kernel_cache import source_key\n"
            "print(os.environ['NUMBA_CACHE_DIR']); print(numba.config.CACHE_DIR)\n"
            "print(source_key())\n")
    env = {**os.environ, ENV_CACHE_DIR: str(tmp_path / "c")}
    env.pop(ENV_MARKER, None)
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=REPO, text=True,
                         capture_output=True, check=True, timeout=120).stdout.split()
    assert out[0] == out[1] == str(tmp_path / "c" / f"gpsdr-{out[2]}")
