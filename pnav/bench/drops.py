"""How many notification-sized puts Zenoh drops on a busy machine: ``python -m pnav.bench.drops``.

A change notification is a session put with Zenoh's default congestion control, DROP: when
the link's transmission queue has no room for ``wait_before_drop`` (Zenoh's default 1 ms),
the message is dropped. This sends ``--n`` puts of a laser scan's notification size (3.3 KB)
at ``--rate`` a second (the bridge's rate at 10 robots is about 600) from one client session
through a router to a subscriber in another, while ``--hogs`` processes keep the cores busy,
and counts what arrived. ``--wait-us`` sets ``wait_before_drop`` on every session (the
router forwards with its own queues, and drops as the publisher does);
``--block`` uses congestion control BLOCK instead (never dropped, but a put then waits as long
as the queue is full). ``--queue`` sets how many batches each link's data queue holds, in
every session: Zenoh's default is 2, and an express put is a batch to itself, so the queue is
full as soon as the link's writer misses a turn; pnav's sessions have 16
(common/config.py ``DATA_QUEUE_BATCHES``). Without ``--queue`` the sessions have Zenoh's 2.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
from multiprocessing.synchronize import Event

import zenoh

from pnav.run.embedded_postgres import free_port

BODY = b"x" * 3300  # a 360-beam scan's notification with its image, about


def _hog(stop: Event) -> None:
    while not stop.is_set():
        sum(range(1000))


def _config(
    mode: str, endpoint: str, wait_us: int | None = None, queue: int | None = None
) -> zenoh.Config:
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    where = "listen/endpoints" if mode == "router" else "connect/endpoints"
    config.insert_json5(where, json.dumps([endpoint]))
    if wait_us is not None:
        key = "transport/link/tx/queue/congestion_control/drop/wait_before_drop"
        config.insert_json5(key, str(wait_us))
    if queue is not None:
        config.insert_json5("transport/link/tx/queue/size/data", str(queue))
    return config


def measure(
    n: int, rate: float, hogs: int, wait_us: int | None, block: bool, queue: int | None = None
) -> dict[str, int]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stop = mp.Event()
    busy = [mp.Process(target=_hog, args=(stop,), daemon=True) for _ in range(hogs)]
    for process in busy:
        process.start()
    router = zenoh.open(_config("router", endpoint, wait_us, queue))
    listener = zenoh.open(_config("client", endpoint, wait_us, queue))
    publisher = zenoh.open(_config("client", endpoint, wait_us, queue))
    got = [0]
    subscriber = listener.declare_subscriber("drops/**", lambda _s: got.__setitem__(0, got[0] + 1))
    try:
        time.sleep(1.0)  # the subscription reaches the router
        control = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        period = 1.0 / rate
        for i in range(n):
            publisher.put(
                f"drops/laser_scan/r{i % 10}", BODY, express=True, congestion_control=control
            )
            time.sleep(period)
        time.sleep(2.0)  # the last ones arrive
        return {"sent": n, "received": got[0], "lost": n - got[0]}
    finally:
        stop.set()
        subscriber.undeclare()
        for session in (publisher, listener, router):
            session.close()
        for process in busy:
            process.join(timeout=5)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pnav.bench.drops", description=__doc__)
    ap.add_argument("--n", type=int, default=3000, help="puts (default 3000)")
    ap.add_argument("--rate", type=float, default=600.0, help="puts a second (default 600)")
    ap.add_argument("--hogs", type=int, default=4, help="busy processes beside it (default 4)")
    ap.add_argument("--wait-us", type=int, help="wait_before_drop, us (Zenoh's default: 1000)")
    ap.add_argument("--block", action="store_true", help="congestion control BLOCK")
    ap.add_argument("--queue", type=int, help="batches in each link's data queue (Zenoh's: 2)")
    args = ap.parse_args(argv)
    figures = measure(args.n, args.rate, args.hogs, args.wait_us, args.block, args.queue)
    how = "BLOCK" if args.block else f"DROP, wait_before_drop {args.wait_us or 'default'} us"
    if args.queue is not None:
        how += f", data queue {args.queue} batches"
    print(f"{how}: {json.dumps(figures)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
