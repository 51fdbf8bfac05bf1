"""reachirl as an installed package: a wheel built from this checkout, installed without -e into a fresh venv (its
dependencies this environment's), runs ``reachirl reproduce --quick`` with its package data and without the source
tree on its path."""

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(cmd, **kw):
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    assert proc.returncode == 0, f"{cmd}: {proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
    return proc


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_wheel_installs_and_reproduces(tmp_path):
    # the wheel, built as `pip install .` builds it; no licence or other build warning
    proc = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", ROOT, "-w", tmp_path / "dist"],
        cwd=tmp_path,
    )
    assert "BuildBackendWarning" not in proc.stderr and "license" not in proc.stderr.lower()
    wheel = next((tmp_path / "dist").glob("reachirl-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    for data in (
        "reachirl/data/markersets/ue-adl.json",
        "reachirl/data/ue_adl_sample/subjects.csv",
        "reachirl/py.typed",
    ):
        assert data in names
    assert any(n.endswith("licenses/LICENSE") for n in names)

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv])
    py = venv / "bin" / "python"
    # its dependencies are this environment's (`make install` installs requirements.lock), seen through a path
    # entry read first (repeating their installation here took most of this test's time), with their own .pth
    # hooks (cmeel's, for Pinocchio and Crocoddyl) but not the checkout's editable install
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    deps = Path(
        _run([sys.executable, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip()
    )
    (site / "00-reachirl-deps.pth").write_text(f"{deps}\n")
    for pth in deps.glob("*.pth"):
        if "reachirl" not in pth.name:
            (site / pth.name).write_text(pth.read_text())
    _run([py, "-m", "pip", "install", "-q", "--no-deps", wheel], cwd=tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"OMP_NUM_THREADS": "1"}
    where = _run([py, "-c", "import reachirl; print(reachirl.__file__)"], cwd=tmp_path, env=env).stdout
    assert str(venv) in where and str(ROOT) not in where  # the installed copy, not the checkout
    _run([py, "-c", "import casadi, crocoddyl, mim_solvers, mujoco, pinocchio"], cwd=tmp_path, env=env)  # both stacks
    proc = _run(
        [
            venv / "bin" / "reachirl",
            "reproduce",
            "--quick",
            "--workers",
            "1",
            "--no-progress",
            "--out",
            tmp_path / "run",
        ],
        cwd=tmp_path,
        env=env,
        timeout=3000,
    )
    assert "RMSE of the joint angles" in proc.stdout
    for f in ("table.md", "table.csv", "results.json", "report.md", "figures/fig2_prediction.png"):
        assert (tmp_path / "run" / f).is_file()
    # package data: the UE-ADL sample and its marker set, through the installed console script
    sample = Path(where.strip()).parent / "data" / "ue_adl_sample"
    _run(
        [
            venv / "bin" / "reachirl",
            "preprocess",
            sample / "ADL001",
            "--subject-info",
            sample / "subjects.csv",
            "--out",
            tmp_path / "adl.npz",
        ],
        cwd=tmp_path,
        env=env,
    )
