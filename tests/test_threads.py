"""The library's threads on a shared machine: it measures the cores other processes keep busy,
steps its parallel kernels (and torch's inference) down to the cores they leave free, leaves
a count the user chose alone, launches no threads for small products, and the trade says when
it was timed on a busy machine."""
import os
import subprocess
import sys
import time

import numba
import numpy as np
import pytest
import scipy.sparse as sp

import anisofem as af
from anisofem.studies import trade as ladder
from anisofem.studies import rungs as ladder_rungs
from anisofem.studies import trade_report
from anisofem import threads
from anisofem.studies.bench_load import Busy
from anisofem.physics.sparse import PARALLEL_MIN_ENTRIES, SparseOperator

CORES = len(threads.cores())


def test_free_threads_are_the_cores_the_others_leave_rounded():
    assert threads.free_threads(0.0, 2, 2) == 2
    assert threads.free_threads(0.4, 2, 2) == 2
    assert threads.free_threads(0.6, 2, 2) == 1
    assert threads.free_threads(1.9, 2, 2) == 1
    assert threads.free_threads(3.0, 2, 2) == 1
    assert threads.free_threads(2.0, 16, 16) == 14
    assert threads.free_threads(0.0, 16, 4) == 4


def test_meter_counts_other_processes_and_not_this_one():
    meter = threads.LoadMeter()
    time.sleep(0.3)
    before = meter.others()  # what else runs on this machine now
    if before > CORES - 1.2:
        pytest.skip(f"the machine is busy ({before:.1f} of {CORES} cores): no core to measure")
    end = time.monotonic() + 0.4
    while time.monotonic() < end:  # this process busy: not "others"
        pass
    assert meter.others() < before + 0.5
    with Busy(1):
        meter.others()
        time.sleep(0.5)
        assert meter.others() > before + 0.6


@pytest.mark.skipif(threads.fixed() is not None, reason="the environment fixes the threads")
def test_parallel_work_steps_down_beside_busy_processes():
    with Busy(CORES):
        threads.available()
        time.sleep(0.3)
        time.sleep(threads.SAMPLE_SECONDS)
        assert threads.parallel_threads() == 1
        assert numba.get_num_threads() == 1


def _in_a_process(env, code):
    clean = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS",
                                                             "NUMBA_NUM_THREADS")}
    done = subprocess.run([sys.executable, "-c", code], env={**clean, **env},
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.split()


@pytest.mark.parametrize("variable", ["OMP_NUM_THREADS", "NUMBA_NUM_THREADS"])
def test_a_count_the_user_chose_wins(variable):
    code = ("import numba, anisofem.threads as t\n"
            "t.parallel_threads()\n"
            "print(t.fixed(), numba.get_num_threads())")
    assert _in_a_process({variable: "1"}, code) == ["1", "1"]
    fixed, _ = _in_a_process({}, code)
    assert fixed == "None"


def test_set_threads_fixes_the_count_and_none_gives_it_back():
    try:
        threads.set_threads(1)
        assert threads.parallel_threads() == 1 and numba.get_num_threads() == 1
        with pytest.raises(ValueError, match="n: threads between 1 and"):
            threads.set_threads(numba.config.NUMBA_NUM_THREADS + 1)
    finally:
        threads.set_threads(None)
    assert threads.fixed() == threads._ENVIRONMENT


def test_small_products_launch_no_threads_and_agree_with_parallel_ones():
    rng = np.random.default_rng(0)
    small = sp.random(200, 200, density=0.05, random_state=1, format="csr")
    large = sp.random(2000, 2000, density=0.02, random_state=2, format="csr")
    assert small.nnz < PARALLEL_MIN_ENTRIES <= large.nnz
    for M, parallel in ((small, False), (large, True)):
        op = SparseOperator.of(M, np.float64)
        assert op.parallel is parallel
        v = rng.standard_normal(M.shape[1])
        np.testing.assert_allclose(op @ v, M @ v, rtol=1e-12, atol=1e-12)


def test_torch_inference_steps_down_beside_busy_processes():
    torch = pytest.importorskip("torch")
    from anisognn.rollout import torch_threads
    if threads.fixed() is not None or CORES < 2:
        pytest.skip("the threads are fixed, or one core")
    torch.set_num_threads(CORES)
    try:
        with Busy(CORES):
            threads.available()
            time.sleep(0.3 + threads.SAMPLE_SECONDS)
            torch_threads()
            assert torch.get_num_threads() == 1
        # the count the caller chose is remembered: set again once the cores are free
        time.sleep(0.5)
        threads.available()
        time.sleep(threads.SAMPLE_SECONDS)
        torch_threads()
        assert torch.get_num_threads() == min(CORES, threads.available())
    finally:
        torch.set_num_threads(1)


def test_trade_records_the_machine_and_warns_when_it_was_busy():
    scene = af.default_scene(af.box_beam(cells=(6, 2, 2)),
                             af.Material.paper(fiber_direction=(1, 0, 0), fiber_stiffness=1e5))
    rungs = ladder_rungs.select_rungs(ladder_rungs.fem_rungs(), ["reduced m5"])
    calm = ladder.trade(scene, steps=10, rungs=rungs, progress=False)
    machine = calm["machine"]
    assert machine["cores"] == CORES and len(machine["load_average_start"]) == 3
    assert all("busy_cores" in r and "timed_twice" in r for r in calm["rungs"])
    with Busy(CORES):
        busy = ladder.trade(scene, steps=10, rungs=rungs, progress=False)
    assert busy["machine"]["busy_cores"] >= ladder.BUSY_CORES
    assert not any("busy" in n for n in busy["notes"])  # said in the table, not a note
    assert any(r["timed_twice"] for r in busy["rungs"])
    table = trade_report.trade_table(busy)
    assert "warning: the machine was busy" in table
    marked = [line[:27].strip() for line in table.splitlines()[2:] if line[27:28] == "*"]
    assert marked and set(marked) <= {"exact", "reduced m5"}


def test_bench_under_load_times_each_rung_idle_and_beside_the_busy_processes(tmp_path, capsys):
    from anisofem.studies import bench_load
    out = tmp_path / "load" / "bench.json"
    report = bench_load.run(busy=1, scenes=("200",), rungs=["reduced m5"], out=str(out),
                            progress=False)
    assert [r["rung"] for r in report["rows"]] == ["exact", "reduced m5"]
    for row in report["rows"]:
        assert row["slowdown"] == pytest.approx(row["loaded_ms"] / row["idle_ms"])
        assert row["loaded_busy_cores"] > row["idle_busy_cores"]
        # on an idle machine the busy process is all the others; where the timing and the busy
        # process share a CPU quota (CI's gave it 0.54 of a core) it gets less than a core
        if row["idle_busy_cores"] < 0.3:
            assert row["loaded_busy_cores"] > 0.3
    printed = capsys.readouterr().out
    assert "beside 1 busy processes" in printed and "reduced m5" in printed
    assert out.exists()
    with pytest.raises(ValueError, match="busy: at least one busy process"):
        bench_load.run(busy=0)
