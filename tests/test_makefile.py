"""`make run`'s set-up of its compiled solvers, read from what make would do (`make -n`: nothing is run)."""

import os
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PREPARE = "reachirl.doc.compile_job prepare 100"

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs make")


def _planned(cache: str) -> str:
    out = subprocess.run(  # REACHIRL_CACHE comes before XDG_CACHE_HOME and ~/.cache, as in reachirl.io.cache_root
        ["make", "-n", "run"], cwd=ROOT, env={**os.environ, "REACHIRL_CACHE": cache}, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    return out.stdout


def _casadi_version() -> str:
    return re.search(r"^casadi==(\S+)$", (ROOT / "requirements.lock").read_text(), flags=re.M).group(1)


def test_make_run_compiles_its_solvers_for_a_cache_that_has_not_got_them(tmp_path):
    plan = _planned(str(tmp_path))
    assert PREPARE in plan
    assert str(tmp_path / f"casadi-{_casadi_version()}" / "make-run-solvers.stamp") in plan  # noted in that cache
    assert plan.index(PREPARE) < plan.index("reachirl reproduce --out results")


def test_make_run_does_not_compile_again_for_a_cache_that_noted_its_solvers(tmp_path):
    stamp = tmp_path / f"casadi-{_casadi_version()}" / "make-run-solvers.stamp"
    stamp.parent.mkdir()
    stamp.touch()
    later = time.time() + 3600  # newer than every source the note depends on
    os.utime(stamp, (later, later))
    plan = _planned(str(tmp_path))
    assert PREPARE not in plan
    assert "reachirl reproduce --out results" in plan


def test_a_cache_path_with_a_space_keeps_the_note_in_the_environment(tmp_path):
    cache = tmp_path / "my cache"
    plan = _planned(str(cache))
    assert "reachirl reproduce --out results" in plan
    assert str(cache) not in plan  # make cannot name a target with a space: the note is .venv's
