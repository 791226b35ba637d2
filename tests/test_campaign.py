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
    seen: list[int] = []
    here = campaign.run_chunks(_square, chunks)
    there = campaign.run_chunks(_square, chunks, cluster.scheduler_address, done=seen.append)
    assert here == there == [(i, i * i + 7) for i in range(20)]
    assert sorted(seen) == list(range(20))


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


def test_an_unreachable_scheduler_is_a_one_line_error(monkeypatch):
    monkeypatch.setattr(campaign, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(MavtuneError, match="cannot reach the Dask scheduler 'tcp://127.0.0.1:9'") as err:
        campaign.run_chunks(_square, [(1, 2)], "tcp://127.0.0.1:9")
    assert "\n" not in str(err.value)
