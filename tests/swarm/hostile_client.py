"""A hostile Zenoh client for the swarm tests, run as its own process (Zenoh's runtime is shared inside a process,
so a callback stalled here must not stall the test's own sessions).

    python hostile_client.py stall ENDPOINT           subscribe to '**' and stop reading at the first sample
    python hostile_client.py burst ENDPOINT KEY N BYTES   put N rejected payloads of BYTES each, blocking puts
"""

from __future__ import annotations

import sys
import time

import zenoh

from mavtune.swarm.transport import zenoh_config


def main(argv: list[str]) -> None:
    mode, endpoint = argv[0], argv[1]
    session = zenoh.open(zenoh_config("client", endpoint, connect_timeout_s=10))
    if mode == "stall":
        session.declare_subscriber("**", lambda sample: time.sleep(3600))
        print("stalling", flush=True)
        time.sleep(3600)
    elif mode == "burst":
        key, n, size = argv[2], int(argv[3]), int(argv[4])
        payload = b"\x00" * size
        for _ in range(n):
            session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
        print("burst sent", flush=True)
        session.close()


if __name__ == "__main__":
    main(sys.argv[1:])
