"""fourws sweep: the rows equal single runs, a raising run is a row with its reason, the
parallel path gives the same rows as the serial one."""

import csv
from concurrent.futures.process import BrokenProcessPool

import pytest

from fourws_bringup.core.closed_loop import run_closed_loop
from fourws_bringup.sweep import load_spec, read_csv, run_sweep, summary_markdown, write_csv

SPEC = """
controllers: [lqr_ff, no_such_preset]
scenarios: [dlc_60_mu05]
seeds: [1, 2]
conditions:
  ideal: {}
  noise: {noise: {y: {sigma: 0.02, tau_s: 1.0}}}
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    path = tmp_path_factory.mktemp("sweep") / "spec.yaml"
    path.write_text(SPEC, encoding="utf-8")
    jobs = load_spec(path)
    return jobs, run_sweep(jobs, workers=2, progress=False), path.parent


def test_the_spec_expands_seeds_only_where_there_is_noise(swept):
    jobs, _, _ = swept
    keys = [j.key for j in jobs]
    assert keys == [("lqr_ff", "dlc_60_mu05", "ideal", 1),
                    ("no_such_preset", "dlc_60_mu05", "ideal", 1),
                    ("lqr_ff", "dlc_60_mu05", "noise", 1),
                    ("no_such_preset", "dlc_60_mu05", "noise", 1),
                    ("lqr_ff", "dlc_60_mu05", "noise", 2),
                    ("no_such_preset", "dlc_60_mu05", "noise", 2)]


def test_rows_equal_single_runs_and_a_raising_run_is_a_row(swept):
    jobs, rows, _ = swept
    for job, row in zip(jobs, rows, strict=True):
        if job.controller == "no_such_preset":
            assert row["completed"] is False and "not found" in row["reason"]
            continue
        single = run_closed_loop(job.scenario, job.controller, condition=job.condition)
        assert row["max_abs_lateral_error_m"] == single.metrics()["max_abs_lateral_error_m"]
        assert row["steps"] == single.steps
    assert rows[2]["max_abs_lateral_error_m"] != rows[4]["max_abs_lateral_error_m"]  # seeds


def test_csv_and_summary(swept):
    jobs, rows, folder = swept
    write_csv(rows, folder / "results.csv")
    with (folder / "results.csv").open(encoding="utf-8") as f:
        table = list(csv.DictReader(f))
    assert len(table) == len(jobs)
    assert list(table[0])[:4] == ["controller", "scenario", "condition", "seed"]
    assert {"completed", "reason", "np_min", "q_y_max"} <= set(table[0])
    md = summary_markdown(rows, jobs)
    assert "| dlc_60_mu05 | noise | lqr_ff | 2 | 0 |" in md
    assert "| dlc_60_mu05 | ideal | no_such_preset | 1 | 1 |" in md
    # the summary rebuilt from the CSV (make_benchmark --from-csv) is the same summary
    assert summary_markdown(read_csv(folder / "results.csv"), jobs) == md


def test_bad_spec_names_the_key(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("controllers: [improved]\nscenarios: [dlc_60_mu05]\nconditions: {a: {}}\n"
                 "workers: 3\n", encoding="utf-8")
    with pytest.raises(ValueError, match="workers"):
        load_spec(p)


@pytest.mark.parametrize(("text", "needle"), [
    ("seeds: 5\n", "seeds"),                                   # was a TypeError
    ("seeds: []\n", "seeds"),                                  # was silently [0]
    ("seeds: [-1]\n", "conditions.a: seed"),                  # aliased another seed's noise
    ("controllers: improved\n", "controllers"),                # was 8 one-letter jobs
    ("conditions: [a]\n", "conditions"),                       # was an AttributeError
    ("conditions: {a: {delay_periods: 1.9}}\n", "conditions.a: delay_periods"),  # truncated
    ("conditions: {a: {delay_periods: null}}\n", "conditions.a: delay_periods"),
    ("conditions: {a: {mpc_overrides: [1]}}\n", "conditions.a: mpc_overrides"),
])
def test_a_bad_value_names_the_file_and_key(tmp_path, text, needle):
    base = {"controllers": "controllers: [improved]\n", "scenarios": "scenarios: [dlc_60_mu05]\n",
            "conditions": "conditions: {a: {}}\n", "seeds": ""}
    base[text.split(":")[0]] = text
    p = tmp_path / "bad.yaml"
    p.write_text("".join(base.values()), encoding="utf-8")
    with pytest.raises(ValueError, match=needle) as err:
        load_spec(p)
    assert str(p) in str(err.value)


def test_groups_and_scenario_paths_relative_to_the_spec(tmp_path):
    (tmp_path / "sc").mkdir()
    src = __import__("fourws_common.resources", fromlist=["config_dir"]).config_dir(
        "fourws_sim") / "scenarios" / "dlc_60_mu05.yaml"
    (tmp_path / "sc" / "mine.yaml").write_text(src.read_text(encoding="utf-8"),
                                               encoding="utf-8")
    p = tmp_path / "spec.yaml"
    p.write_text("seeds: [0]\ngroups:\n"
                 "  - {controllers: [lqr_ff], scenarios: [sc/mine.yaml], conditions: {a: {}}}\n"
                 "  - {controllers: [improved], scenarios: [dlc_90_mu06], "
                 "conditions: {b: {delay_periods: 1}}}\n", encoding="utf-8")
    jobs = load_spec(p)
    assert [j.key for j in jobs] == [("lqr_ff", str(tmp_path / "sc" / "mine.yaml"), "a", 0),
                                     ("improved", "dlc_90_mu06", "b", 0)]
    p.write_text("groups: [{controllers: [lqr_ff], scenarios: [x]}]\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"groups\[0\].*conditions"):
        load_spec(p)


def test_a_controller_preset_file_is_relative_to_the_spec_like_a_scenario(tmp_path):
    """The one rule (core.configs.beside): a relative .yaml entry is beside the spec (``..``
    resolved), a preset name or an absolute path stays as written."""
    from fourws_bringup.core.configs import beside

    (tmp_path / "study").mkdir()
    p = tmp_path / "study" / "spec.yaml"
    p.write_text("controllers: [mine.yaml, lqr_ff, /abs/other.yaml]\n"
                 "scenarios: [../sc/x.yaml]\nconditions: {a: {}}\n", encoding="utf-8")
    jobs = load_spec(p)
    assert [j.controller for j in jobs] == [str(tmp_path / "study" / "mine.yaml"), "lqr_ff",
                                            "/abs/other.yaml"]
    assert {j.scenario for j in jobs} == {str(tmp_path / "sc" / "x.yaml")}
    assert beside(p, "dlc_60_mu05") == "dlc_60_mu05"


def test_the_shipped_benchmark_spec_loads_and_covers_the_issue():
    from pathlib import Path

    spec = Path(__file__).resolve().parents[2] / "benchmarks" / "robustness.yaml"
    jobs = load_spec(spec)
    from fourws_bringup.core.configs import list_controllers

    assert sorted({j.controller for j in jobs}) == list_controllers()   # every shipped preset
    noisy = {j.condition.name for j in jobs if j.condition.seed == 4}
    assert noisy == {"noise_gm", "noise_white", "noise_velocity", "all", "all_ekf"}  # noise
    for j in jobs:
        __import__("fourws_sim.core.scenario", fromlist=["load_scenario"]).load_scenario(
            j.scenario)


def test_the_distributed_path_gives_the_same_csv_as_the_local_one(swept, tmp_path):
    """A Dask distributed cluster of two worker processes (``LocalCluster``, the same client
    code as ``--scheduler tcp://host:8786``) returns the local sweep's rows, in job order: the
    CSVs are byte-identical, the raising run included."""
    distributed = pytest.importorskip("distributed")
    jobs, rows, _ = swept
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = run_sweep(jobs, progress=False, scheduler=cluster.scheduler_address)
    write_csv(rows, tmp_path / "local.csv")
    write_csv(remote, tmp_path / "dask.csv")
    assert (tmp_path / "dask.csv").read_bytes() == (tmp_path / "local.csv").read_bytes()


def test_an_unreachable_scheduler_is_a_clear_error(tmp_path, capsys):
    from fourws_bringup.sweep import sweep_cli

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    code = sweep_cli(str(spec), str(tmp_path / "out"), 1, scheduler="tcp://127.0.0.1:9",
                     connect_timeout_s=2.0)
    assert code == 2 and "scheduler tcp://127.0.0.1:9" in capsys.readouterr().err


def test_a_run_uses_one_blas_thread_whatever_the_process(swept, monkeypatch):
    """run_job limits every BLAS to one thread while the run lasts (a multi-threaded BLAS
    may sum in another order, and a near-chaotic noisy run turns the last bit into
    millimetres: the row would depend on the worker layout), and gives the limit back."""
    from threadpoolctl import threadpool_info, threadpool_limits

    import fourws_bringup.core.closed_loop as closed_loop
    from fourws_bringup import sweep

    seen = []

    def spy(*args, **kwargs):
        seen.append([i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"])
        raise RuntimeError("stop here")

    monkeypatch.setattr(closed_loop, "run_closed_loop", spy)
    jobs, _, _ = swept
    with threadpool_limits(limits=2, user_api="blas"):
        row = sweep.run_job(jobs[0])
        after = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    assert seen and seen[0] and set(seen[0]) == {1}, seen
    assert "stop here" in row["reason"] and row["completed"] is False
    assert after and max(after) <= 2


def test_the_limit_bench_spec_loads_every_scenario_and_covers_the_issue():
    """benchmarks/limits.yaml: both worlds, both tyre models, five seeds under realistic,
    every scenario loads, and the allocation methods include the fair baseline."""
    from pathlib import Path

    from fourws_sim.core.scenario import load_scenario

    spec = Path(__file__).resolve().parents[2] / "benchmarks" / "limits.yaml"
    jobs = load_spec(spec)
    conds = {j.condition.name for j in jobs}
    assert {"ideal_linear", "ideal_friction", "realistic_linear",
            "realistic_friction", "realistic_production"} <= conds
    assert {j.condition.seed for j in jobs if j.condition.name == "realistic_friction"} == \
        set(range(5))
    for name in {j.scenario for j in jobs}:
        load_scenario(name)


def _fake_rows(monkeypatch, stop_at: int, exc: BaseException):
    """run_job answering a row per job until job ``stop_at``, which raises ``exc``."""
    import fourws_bringup.sweep as sweep

    calls = []

    def fake(job):
        calls.append(job)
        if len(calls) > stop_at:
            raise exc
        return {**dict(zip(sweep.LEAD, job.key, strict=True)), "completed": True,
                "max_abs_lateral_error_m": 0.01 * len(calls)}

    monkeypatch.setattr(sweep, "run_job", fake)


def test_an_existing_folder_is_refused_and_force_replaces_only_a_sweep(tmp_path, monkeypatch,
                                                                        capsys):
    from fourws_bringup.sweep import sweep_cli

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    out = tmp_path / "out"
    _fake_rows(monkeypatch, 99, RuntimeError())
    assert sweep_cli(str(spec), str(out), 1) == 0
    first = (out / "results.csv").read_text(encoding="utf-8")
    assert sweep_cli(str(spec), str(out), 1) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "results.csv").read_text(encoding="utf-8") == first
    assert sweep_cli(str(spec), str(out), 1, force=True) == 0
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me", encoding="utf-8")
    assert sweep_cli(str(spec), str(other), 1, force=True) == 2
    assert (other / "notes.txt").read_text(encoding="utf-8") == "keep me"


@pytest.mark.parametrize(("exc", "code"), [(KeyboardInterrupt(), 130),
                                           (BrokenProcessPool("a worker died"), 1)])
def test_an_interrupted_sweep_keeps_the_rows_it_finished(tmp_path, monkeypatch, capsys, exc,
                                                         code):
    import json

    from fourws_bringup.sweep import JOURNAL, sweep_cli

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    out = tmp_path / "out"
    _fake_rows(monkeypatch, 3, exc)
    assert sweep_cli(str(spec), str(out), 1) == code
    assert "3 finished rows" in capsys.readouterr().err
    rows = [json.loads(line) for line in (out / JOURNAL).read_text(encoding="utf-8")
            .splitlines()]
    assert [r["job"] for r in rows] == [0, 1, 2]
    assert [r["max_abs_lateral_error_m"] for r in rows] == [0.01, 0.02, 0.03]
    assert not (out / "results.csv").exists()


def test_a_failed_csv_write_leaves_the_old_file_whole(tmp_path, monkeypatch):
    path = tmp_path / "results.csv"
    rows = [{"controller": "a", "scenario": "s", "condition": "c", "seed": 0, "x": 1.0}] * 3
    write_csv(rows, path)
    before = path.read_text(encoding="utf-8")

    def full_disk(self, row):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(csv.DictWriter, "writerow", full_disk)
    with pytest.raises(OSError):
        write_csv(rows[:1], path)
    assert path.read_text(encoding="utf-8") == before
    assert [p.name for p in tmp_path.iterdir()] == ["results.csv"]


def test_a_sweep_that_fails_before_its_first_row_leaves_the_folder_retryable(tmp_path,
                                                                            monkeypatch):
    from fourws_bringup.sweep import JOURNAL, sweep_cli

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC, encoding="utf-8")
    out = tmp_path / "out"
    _fake_rows(monkeypatch, 0, KeyboardInterrupt())
    assert sweep_cli(str(spec), str(out), 1) == 130
    assert not (out / JOURNAL).exists() and not any(out.iterdir())
    _fake_rows(monkeypatch, 99, RuntimeError())
    assert sweep_cli(str(spec), str(out), 1) == 0          # the retry needs no --force
