"""`reachirl bench`'s checks before any suite runs: a report folder beside --out that cannot be one, a suite file
that is missing. Each is one line and exit 2, with nothing timed first."""

from __future__ import annotations

from reachirl.cli import bench, main


def test_the_irl_suites_report_folder_is_checked_before_any_suite_runs(tmp_path, capsys, monkeypatch):
    ran = []
    monkeypatch.setattr(bench, "_load", lambda suite: ran.append(suite))  # a suite that ran would be listed
    (tmp_path / "bench_irl").write_text("mine\n")
    assert main(["bench", "doc", "irl", "--quick", "--out", str(tmp_path / "b.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(
        f"{tmp_path / 'bench_irl'}: the irl suite's report folder (beside --out): exists and is not a folder"
    ), err
    assert ran == [] and (tmp_path / "bench_irl").read_text() == "mine\n" and not (tmp_path / "b.json").exists()


def test_a_missing_suite_is_said_before_the_others_run(tmp_path, capsys, monkeypatch):
    bench_dir = tmp_path / "benchmarks"
    bench_dir.mkdir()
    (bench_dir / "bench_doc.py").write_text("def run(**kw):\n    raise AssertionError('the doc suite ran')\n")
    monkeypatch.setattr(bench, "_bench_dir", lambda: bench_dir)
    assert main(["bench", "doc", "predict", "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[-1].endswith(
        f"{bench_dir / 'bench_predict.py'}: benchmark suite 'predict' not found; `reachirl bench` runs from a "
        "source checkout"
    ), err
