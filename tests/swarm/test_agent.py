"""The agent's state machine without a network: envelope, idempotence, start discipline."""

from __future__ import annotations

import math

import pytest

from mavtune.swarm.agent import Agent, check_envelope, decimate
from mavtune.swarm.config import SwarmConfig
from mavtune.swarm.messages import Ack, Assignment, Codec, Finish, Hello, Probe, Result, Start, Welcome, vehicle_key
from mavtune.swarm.transport import Keys
from mavtune.swarm.vehicles import FleetVehicle, ToyFleet
from mavtune.fleet import Trace

from .conftest import LinkStub

KEY = "test key of at least 16 chars"
CODEC = Codec("s", vehicle_key(KEY, "v0"))  # the agent v0 is given the swarm key: it seals with its own
RUN = "1" * 32


class Recorder(LinkStub):
    """Stands in for the Zenoh link: keeps the messages the agent publishes."""

    def put(self, key, payload):
        self.sent.append(CODEC.decode(payload))


CHALLENGE = "c" * 32


def probed(agent, run=RUN) -> Hello:
    """The hello the agent answers a probe of `run` with."""
    agent.handle("probe", CODEC.encode(Probe(session="s", run=run, vehicle=agent.id, challenge=CHALLENGE)))
    return of(agent, Hello)[-1]


def joined(agent, run=RUN):
    """The agent after answering the probe of `run` and being welcomed (its nonce for that run is agent._nonce)."""
    hello = probed(agent, run)
    agent.handle("welcome", CODEC.encode(Welcome(session="s", run=run, agent=hello.agent, vehicle=agent.id)))
    return agent


def make(envelope=None, policy="refuse", vehicle=None):
    cfg = SwarmConfig(session="s", key=KEY, envelope=envelope or {}, envelope_policy=policy)
    vehicle = vehicle or FleetVehicle(ToyFleet(1, seed=1), "toy")
    agent = joined(Agent("v0", vehicle, cfg, Recorder()))
    return agent, vehicle, Keys("s")


def msg(agent, kind, **fields):
    """A coordinator message of the agent's run, bound to its nonce."""
    return kind(session="s", run=agent.run_id, agent=agent._nonce, vehicle="v0", **fields)


def send(agent, keys, m):
    agent.handle(keys.to("v0"), CODEC.encode(m))


def of(agent, kind):
    return [m for m in agent.link.sent if isinstance(m, kind)]


def test_assignment_then_start_flies_once_and_repeats_resend():
    agent, _, keys = make()
    a = msg(agent, Assignment, round=3, gains={"kp": 0.4, "kd": 0.2})
    send(agent, keys, a)
    assert of(agent, Ack)[-1].accepted and agent.flights_flown == 0  # no flight before the start
    send(agent, keys, msg(agent, Start, round=3))
    send(agent, keys, msg(agent, Start, round=3))
    send(agent, keys, a)
    results = of(agent, Result)
    assert agent.flights_flown == 1 and len(results) == 3
    assert results[1].resent and results[2].resent and results[0].cost == results[2].cost


def test_start_without_assignment_or_for_others_does_nothing():
    agent, _, keys = make()
    send(agent, keys, msg(agent, Start, round=1))
    send(agent, keys, msg(agent, Assignment, round=2, gains={"kp": 0.4}))
    send(agent, keys, msg(agent, Start, round=2).model_copy(update={"vehicle": "v1"}))
    send(agent, keys, msg(agent, Start, round=1))
    assert agent.flights_flown == 0 and not of(agent, Result)


@pytest.mark.parametrize("gains", [{"kp": 1.2}, {"kp": -0.1}, {"kp": math.nan}, {"kd": math.inf}])
def test_out_of_envelope_or_non_finite_gains_are_never_applied(gains):
    agent, vehicle, keys = make(envelope={"kp": (0.0, 1.0)})
    send(agent, keys, msg(agent, Assignment, round=0, gains=gains))
    send(agent, keys, msg(agent, Start, round=0))
    assert vehicle._gains is None and agent.flights_flown == 0
    assert of(agent, Ack)[-1].accepted is False


def test_clamp_policy_flies_the_clamped_gains():
    gains, why = check_envelope({"kp": 1.5, "kd": 0.2}, {"kp": (0.0, 0.8)}, "clamp")
    assert gains == {"kp": 0.8, "kd": 0.2} and "clamped" in why
    agent, vehicle, keys = make(envelope={"kp": (0.0, 0.8)}, policy="clamp")
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 1.5, "kd": 0.2}))
    send(agent, keys, msg(agent, Start, round=0))
    assert vehicle._gains == {"kp": 0.8, "kd": 0.2} and of(agent, Result)[0].gains == {"kp": 0.8, "kd": 0.2}


def test_decimate_keeps_at_most_n_points_and_the_last():
    tr = Trace(list(range(1000)), [0.0] * 1000, list(range(1000)))
    d = decimate(tr, 100)
    assert len(d.t_s) <= 100 and d.t_s[0] == 0 and d.t_s[-1] == 999
    assert decimate(tr, 0) is None and decimate(tr, 5000) is tr


def test_same_round_with_other_gains_is_flown_again_not_answered_from_the_store():
    agent, vehicle, keys = make()
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 0.4, "kd": 0.2}))
    send(agent, keys, msg(agent, Start, round=0))
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 0.9, "kd": 0.2}))
    send(agent, keys, msg(agent, Start, round=0))
    results = of(agent, Result)
    assert agent.flights_flown == 2 and [r.gains["kp"] for r in results] == [0.4, 0.9]
    assert not results[1].resent and results[1].cost != results[0].cost


def test_gains_the_backend_refuses_are_refused_at_assignment_and_never_applied():
    from mavtune.swarm.vehicles import sim_vehicle

    agent, vehicle, keys = make(vehicle=sim_vehicle(seed=0))
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 1.5, "kd": 0.2}))
    send(agent, keys, msg(agent, Start, round=0))
    ack = of(agent, Ack)[-1]
    assert ack.accepted is False and "kp" in ack.reason
    assert vehicle._gains is None and agent.flights_flown == 0


class Crashing(FleetVehicle):
    """A vehicle whose flight raises (a bug or an I/O error), optionally after a delay."""

    def __init__(self, delay_s=0.0):
        super().__init__(ToyFleet(1), "toy")
        self.delay_s = delay_s

    def fly(self, round_id):
        import time

        time.sleep(self.delay_s)
        raise OSError("link gone")


def test_a_crashed_flight_is_lost_not_failed():
    agent, _, keys = make(vehicle=Crashing())
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 0.4, "kd": 0.2}))
    send(agent, keys, msg(agent, Start, round=0))
    result = of(agent, Result)[0]
    assert result.status.value == "lost" and "link gone" in result.info["detail"]


class ClosingRecorder(Recorder):
    """A link that refuses to publish once closed."""

    closed = False

    def put(self, key, payload):
        assert not self.closed, "published on a closed link"
        super().put(key, payload)

    def close(self):
        self.closed = True


def test_close_waits_for_the_flight_under_way_and_its_result():
    import threading

    cfg = SwarmConfig(session="s", key=KEY)
    agent, keys = joined(Agent("v0", Crashing(delay_s=0.3), cfg, ClosingRecorder())), Keys("s")
    t = threading.Thread(target=agent.run, daemon=True)
    t.start()
    agent._on_sample(keys.to("v0"), CODEC.encode(msg(agent, Assignment, round=0, gains={"kp": 0.4, "kd": 0.2})))
    agent._on_sample(keys.to("v0"), CODEC.encode(msg(agent, Start, round=0)))
    import time

    deadline = time.monotonic() + 5
    while agent.state.value != "flying" and time.monotonic() < deadline:
        time.sleep(0.01)
    agent.close(timeout_s=10)
    t.join(timeout=5)
    assert not t.is_alive() and len(of(agent, Result)) == 1


class Releases(FleetVehicle):
    """A toy vehicle that records every release (what a MAVLink vehicle does: originals back, or tuned gains)."""

    def __init__(self):
        super().__init__(ToyFleet(1), "toy")
        self.released = []

    def release(self, tuned=None):
        self.released.append(tuned)


def test_the_vehicle_is_released_once_when_the_run_ends_or_the_coordinator_goes():
    agent, vehicle, keys = make(vehicle=Releases())

    def coordinator_gone(run=RUN):
        agent._on_coordinator(keys.coordinator(run), False)
        agent._check_coordinator()

    coordinator_gone()  # nothing applied yet: nothing to release
    assert vehicle.released == []
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 0.4, "kd": 0.2}))
    send(agent, keys, msg(agent, Finish, gains={"kp": 0.5, "kd": 0.3}))
    assert vehicle.released == [{"kp": 0.5, "kd": 0.3}]
    assert of(agent, Ack)[-1].round == -1 and of(agent, Ack)[-1].reason == "released"
    coordinator_gone()  # the coordinator closing after Finish releases nothing twice
    assert len(vehicle.released) == 1
    send(agent, keys, msg(agent, Assignment, round=1, gains={"kp": 0.6, "kd": 0.2}))
    coordinator_gone("2" * 32)  # another run's coordinator going away means nothing to this one
    assert len(vehicle.released) == 1
    coordinator_gone()  # a crashed coordinator: originals back
    assert vehicle.released == [{"kp": 0.5, "kd": 0.3}, None]


def test_messages_of_another_run_or_nonce_and_stale_rounds_move_nothing():
    """Replays: an earlier run's messages (even one this agent served), another agent's nonce, an older round."""
    agent, vehicle, keys = make(vehicle=Releases())
    first_nonce = agent._nonce
    send(agent, keys, msg(agent, Assignment, round=5, gains={"kp": 0.4, "kd": 0.2}))
    old_finish = msg(agent, Finish, gains={"kp": 0.0, "kd": 0.0})
    joined(agent, "2" * 32)  # a new coordinator run: a fresh nonce
    assert agent.run_id == "2" * 32 and agent._nonce != first_nonce
    send(agent, keys, old_finish)  # replay from the earlier run
    send(agent, keys, msg(agent, Finish, gains={"kp": 0.1, "kd": 0.1}).model_copy(update={"agent": "f" * 32}))
    probed(agent, RUN)  # a replayed probe of the earlier run does not take the agent back
    assert agent.run_id == "2" * 32
    send(agent, keys, old_finish)
    old_welcome = Welcome(session="s", run=RUN, agent=first_nonce, vehicle="v0")
    send(agent, keys, old_welcome)  # nor does its earlier welcome: the nonce offered now is another
    assert agent.run_id == "2" * 32
    assert vehicle.released == [] and not of(agent, Ack)[1:]
    send(agent, keys, msg(agent, Assignment, round=8, gains={"kp": 0.4, "kd": 0.2}))
    send(agent, keys, msg(agent, Assignment, round=7, gains={"kp": 0.9, "kd": 0.9}))  # older than round 8
    assert [a.round for a in of(agent, Ack)] == [5, 8]
    hellos = of(agent, Hello)
    assert [h.run for h in hellos] == [RUN, "2" * 32, RUN] and len({h.agent for h in hellos}) == 3
    assert all(h.challenge == CHALLENGE for h in hellos)


def test_a_probe_commits_nothing_until_the_nonce_comes_back_sealed():
    """Challenge–response: a (replayed) probe earns a hello; only a message sealed with the vehicle's key that
    carries the offered nonce back makes the agent serve that run, and a restarted agent offers another nonce."""
    agent, vehicle, keys = make(vehicle=Releases())
    served = agent.run_id
    hello = probed(agent, "3" * 32)
    assert agent.run_id == served  # still the run it served
    send(agent, keys, Assignment(session="s", run="3" * 32, agent="e" * 32, vehicle="v0", round=0, gains={"kp": 0.1}))
    assert agent.run_id == served and not of(agent, Ack)  # a guessed nonce commits nothing
    send(agent, keys, Assignment(session="s", run="3" * 32, agent=hello.agent, vehicle="v0", round=0,
                                 gains={"kp": 0.1, "kd": 0.2}))
    assert agent.run_id == "3" * 32 and of(agent, Ack)[-1].accepted  # the offered nonce sealed back: committed
    restarted = Agent("v0", FleetVehicle(ToyFleet(1, seed=1), "toy"), agent.config, Recorder())
    assert probed(restarted, "3" * 32).agent != hello.agent and restarted.run_id is None


def test_tuned_gains_outside_the_envelope_are_not_kept():
    agent, vehicle, keys = make(envelope={"kp": (0.0, 0.5)}, vehicle=Releases())
    send(agent, keys, msg(agent, Assignment, round=0, gains={"kp": 0.4, "kd": 0.2}))
    send(agent, keys, msg(agent, Finish, gains={"kp": 0.9, "kd": 0.2}))
    assert vehicle.released == [None]
