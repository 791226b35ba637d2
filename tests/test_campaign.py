"""Campaigns on Dask: a LocalCluster of two worker processes on 127.0.0.1 gives the in-process results, also when
a worker is killed in the middle; a scheduler that cannot be reached is a one-line error."""

import os
import signal

import numpy as np
import pytest

from mavtune import campaign
from mavtune.errors import MavtuneError
from mavtune.sim import surface as surf
from mavtune.sim.scenario import Scenario

distributed = pytest.importorskip("distributed")
pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

SC = Scenario(settle_s=0.5, primitive_s=4.0)


@pytest.fixture(scope="module")
def cluster():
    """Two single-threaded worker processes (restarted by their nannies when killed), loopback only."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, worker_dashboard_address=None) as c:
        yield c


def _square(x: int, y: int) -> tuple[int, int]:
    return x, x * x + y


def test_chunks_come_back_in_order_here_and_on_the_cluster(cluster):
    chunks = [(i, 7) for i in range(20)]
    seen: list[tuple[int, tuple[int, int]]] = []
    here = campaign.run_chunks(_square, chunks)
    there = campaign.run_chunks(_square, chunks, cluster.scheduler_address, done=lambda i, r: seen.append((i, r)))
    assert here == there == [(i, i * i + 7) for i in range(20)]
    assert sorted(seen) == list(enumerate(here))


def test_surface_on_the_cluster_is_the_local_surface(cluster, tmp_path):
    ticks: list[tuple[int, int]] = []
    local = surf.compute_surface(5, 3, SC, seed=4, chunk=7)
    remote = surf.compute_surface(5, 3, SC, seed=4, chunk=7, scheduler=cluster.scheduler_address,
                                  progress=lambda done, total: ticks.append((done, total)))
    surf.write_csv(local, tmp_path / "local.csv")
    surf.write_csv(remote, tmp_path / "remote.csv")
    assert (tmp_path / "local.csv").read_bytes() == (tmp_path / "remote.csv").read_bytes()
    np.testing.assert_array_equal(local.failed, remote.failed)
    assert [d for d, _ in ticks] == sorted(d for d, _ in ticks) and ticks[-1] == (75, 75)


def test_a_worker_killed_mid_campaign_leaves_the_same_csv(cluster, tmp_path):
    client = distributed.Client(cluster.scheduler_address, set_as_default=False)
    try:
        pids = client.run(os.getpid)
        killed: list[int] = []

        def kill_one(done: int, total: int) -> None:
            if not killed:  # after the first chunk: the rest is still queued or running on both workers
                assert done < total
                victim = max(pids.values())
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        remote = surf.compute_surface(6, 4, SC, seed=9, chunk=4, scheduler=cluster.scheduler_address,
                                      progress=kill_one)
        local = surf.compute_surface(6, 4, SC, seed=9, chunk=4)
        surf.write_csv(local, tmp_path / "local.csv")
        surf.write_csv(remote, tmp_path / "remote.csv")
        assert (tmp_path / "local.csv").read_bytes() == (tmp_path / "remote.csv").read_bytes()
        assert killed and killed[0] not in client.run(os.getpid).values()
    finally:
        client.close()


@pytest.mark.slow
def test_tuning_and_variant_runs_on_the_cluster_are_the_local_runs(cluster):
    from mavtune.experiments import extensions as ext
    from mavtune.experiments.reproduce import tuning_run

    runs = [("avg", 0.0, 100, 10.0), ("split", 0.9, 102, 0.0)]
    variants = [(ext.VARIANTS[3], 0, 5), (ext.VARIANTS[7], 1, 5)]  # split with speculation; 8 vehicles
    for fn, chunks in ((tuning_run, runs), (ext.variant_run, variants)):
        here = campaign.run_chunks(fn, chunks)
        there = campaign.run_chunks(fn, chunks, cluster.scheduler_address)
        if fn is tuning_run:
            here = [(r.gains, [(rd.assignments, rd.costs) for rd in r.rounds], r.flights) for r in here]
            there = [(r.gains, [(rd.assignments, rd.costs) for rd in r.rounds], r.flights) for r in there]
        assert repr(here) == repr(there)  # repr: NaN costs compare equal as text


@pytest.mark.slow
def test_a_bank_built_on_the_cluster_is_the_local_bank(cluster, tmp_path):
    import json

    from mavtune.bank import build
    from mavtune.config import load_config

    def config_for(payload: float):
        return load_config(None, {"tuning.seed": 3, "tuning.strategy": "split", "sim.payload_kg": payload})

    here = build([0.0, 0.9], tmp_path / "here", config_for)
    there = build([0.0, 0.9], tmp_path / "there", config_for, scheduler=cluster.scheduler_address)
    assert [(e.mass_kg, e.gains) for e in here.entries] == [(e.mass_kg, e.gains) for e in there.entries]
    for e in there.entries:  # the run folders came back from the workers, journal and result included
        folder = tmp_path / "there" / e.source.split("/")[-1]
        assert json.loads((folder / "result.json").read_text())["gains"] == e.gains
        assert (folder / "journal.sqlite").stat().st_size > 0


def test_an_unreachable_scheduler_is_a_one_line_error(monkeypatch):
    monkeypatch.setattr(campaign, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(MavtuneError, match="cannot reach the Dask scheduler 'tcp://127.0.0.1:9'") as err:
        campaign.run_chunks(_square, [(1, 2)], "tcp://127.0.0.1:9")
    assert "\n" not in str(err.value)
