"""Resumable studies: SIGKILL `lightcurve compare` midway and resume; changed-study refusal."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import lightcurve.studies.runner as runner
from lightcurve.errors import InputError
from lightcurve.studies.study import load_study

ROOT = Path(__file__).resolve().parents[2]


def _numbers(path):
    doc = json.loads(path.read_text())
    for c in doc["cells"]:
        c.pop("runtime_s_median")
    return doc


def _snapshot(runs_dir):
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in runs_dir.glob("*.h5")
            if not p.name.startswith(".")}


def test_killed_study_resumes_without_rerun_or_loss(tmp_path, make_study, monkeypatch):
    study_file = make_study(tmp_path, runs=20)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "lightcurve", "compare", str(study_file), "-o",
                             str(out), "--workers", "2", "-q"], env=env, cwd=tmp_path,
                            start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    runs_dir = out / "runs"
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if runs_dir.is_dir() and len(_snapshot(runs_dir)) >= 3:
                break
            time.sleep(0.01)
        assert proc.poll() is None, f"compare ended before it could be killed: {proc.communicate()}"
        os.kill(proc.pid, signal.SIGKILL)  # the process running `lightcurve compare`
    finally:
        proc.wait(timeout=30)
        try:  # its pool workers (same new session/process group, started by this test)
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.stdout.close()
        proc.stderr.close()
    before = _snapshot(runs_dir)
    study = load_study(study_file)
    total = len(study.tasks())
    assert 3 <= len(before) < total, "the kill must land midway"
    assert not (out / "summary.json").exists()

    calls = []
    real = runner.execute_task

    def counting(task):
        calls.append(task.run_id)
        return real(task)

    monkeypatch.setattr(runner, "execute_task", counting)
    summary = runner.run_study(study, out, workers=1, progress=False, write_report=False)
    after = _snapshot(runs_dir)
    # no finished run was rerun: exactly the missing ones were executed, the stored files are
    # untouched (same inode and modification time)
    assert sorted(calls) == sorted(t.run_id for t in study.tasks() if t.run_id + ".h5" not in before)
    assert all(after[k] == v for k, v in before.items())
    # none lost: every run exists exactly once
    assert sorted(after) == sorted(t.run_id + ".h5" for t in study.tasks())
    assert [c["runs"] + c["failures"] for c in summary["cells"]] == [20, 20]
    assert all(c["missing"] == 0 for c in summary["cells"])
    assert not list(runs_dir.glob(".*"))  # stale temporary files cleaned
    # and the numbers equal an uninterrupted study's
    monkeypatch.setattr(runner, "execute_task", real)
    runner.run_study(study, tmp_path / "fresh", workers=1, progress=False, write_report=False)
    assert _numbers(out / "summary.json") == _numbers(tmp_path / "fresh" / "summary.json")


def test_changed_study_refused_unless_force(tmp_path, make_study):
    study_file = make_study(tmp_path, filters=("ukf",), runs=2)
    out = tmp_path / "out"
    runner.run_study(load_study(study_file), out, workers=1, progress=False, write_report=False)
    old_runs = set(p.name for p in (out / "runs").glob("*.h5"))
    assert len(old_runs) == 2
    # rerunning the same study is a no-op resume
    runner.run_study(load_study(study_file), out, workers=1, progress=False, write_report=False)
    study_file.write_text(study_file.read_text().replace("sigma_theta_deg = [3.0]",
                                                         "sigma_theta_deg = [5.0]"))
    changed = load_study(study_file)
    with pytest.raises(InputError, match="different study") as ei:
        runner.run_study(changed, out, workers=1, progress=False, write_report=False)
    assert "--force" in str(ei.value)
    # the CLI says so in one line, exit code 2
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "lightcurve", "compare", str(study_file), "-o",
                        str(out), "-q", "--workers", "1"], env=env, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "different study" in r.stderr, r.stderr
    assert set(p.name for p in (out / "runs").glob("*.h5")) == old_runs  # nothing touched
    s = runner.run_study(changed, out, workers=1, progress=False, write_report=False, force=True)
    new_runs = set(p.name for p in (out / "runs").glob("*.h5"))
    assert len(new_runs) == 2 and not (new_runs & old_runs)  # old runs discarded
    assert s["cells"][0]["sigma_theta_deg"] == 5.0


def test_code_change_refused_unless_force(tmp_path, make_study, monkeypatch):
    """The study hash covers the package version and source hash: a stored study made
    by other code is not resumed (the message says the code changed) unless --force."""
    import lightcurve.studies.study as st

    study_file = make_study(tmp_path, filters=("ukf",), runs=2)
    out = tmp_path / "out"
    study = load_study(study_file)
    fp = st.code_fingerprint()
    assert fp["n_source_files"] > 50 and len(fp["source_sha256"]) == 64
    h0 = study.hash
    runner.run_study(study, out, workers=1, progress=False, write_report=False)
    meta = json.loads((out / "study.json").read_text())
    assert meta["source_sha256"] == fp["source_sha256"] and meta["input_hash"] == study.input_hash
    summ = json.loads((out / "summary.json").read_text())
    assert summ["package_version"] == fp["package_version"]
    # an edited source file changes the fingerprint (simulated: the real files stay untouched)
    monkeypatch.setattr(st, "code_fingerprint",
                        lambda: dict(fp, source_sha256="0" * 64))
    assert study.hash != h0 and study.input_hash == meta["input_hash"]
    with pytest.raises(InputError, match="code changed") as ei:
        runner.run_study(study, out, workers=1, progress=False, write_report=False)
    assert "--force" in str(ei.value)
    before = {p.name for p in (out / "runs").glob("*.h5")}
    s = runner.run_study(study, out, workers=1, progress=False, write_report=False, force=True)
    assert [c["runs"] for c in s["cells"]] == [2]
    assert json.loads((out / "study.json").read_text())["source_sha256"] == "0" * 64
    assert {p.name for p in (out / "runs").glob("*.h5")} == before  # rerun, same run ids
    # the tree hash sees a one-byte edit, a new file and a rename, and ignores __pycache__
    import lightcurve

    pkg = Path(lightcurve.__file__).parent
    assert st.source_tree_hash(pkg) == (fp["source_sha256"], fp["n_source_files"])
    tree = tmp_path / "tree"
    (tree / "sub" / "__pycache__").mkdir(parents=True)
    (tree / "a.py").write_text("x = 1\n")
    (tree / "sub" / "b.py").write_text("y = 2\n")
    h1 = st.source_tree_hash(tree)
    (tree / "sub" / "__pycache__" / "b.py").write_text("junk")
    assert st.source_tree_hash(tree) == h1 and h1[1] == 2
    (tree / "a.py").write_text("x = 2\n")
    h2 = st.source_tree_hash(tree)
    assert h2 != h1
    (tree / "c.py").write_text("")
    assert st.source_tree_hash(tree)[0] != h2[0]
    (tree / "c.py").rename(tree / "d.py")
    assert st.source_tree_hash(tree)[0] not in (h1[0], h2[0])
