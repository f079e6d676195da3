"""Benchmark of the bridge's two legs of the sense-to-act loop; prints figures and JSON.

``python -m pnav.bench.bridge [--seconds 10] [--robots 1] [--burst 3000] [--json FILE]``

Starts its own embedded Postgres and loopback Zenoh router, runs ``python -m services.bridge``
as a separate process (as deployed), and plays the sim from this process:

1. steady: after one warm-up sample per stream (not measured: a new Zenoh publisher's first
   sample is slow once), odometry at 30 Hz and scans at 5 Hz per robot for ``--seconds``.
   Sensor-to-row latency = arrival of the row's change notification here minus the publish
   time of that message (same machine, same monotonic clock). The contract payload carries
   no send time, so each message is identified by its ``seq``: after the run the rows'
   ``(id, seq)`` are read back, and a notification for id K marks every message up to K's
   seq as visible. ``received_at`` latency is the row's ``received_at`` (Postgres clock)
   minus the publish wall time, i.e. without the commit and the notification hop.
2. burst: ``--burst`` odometry messages back to back, for throughput and batching.
3. commands: a command2robot row + notification at 20 Hz, latency to its cmd_vel.

For scale, ``zenoh_hop`` is the same machine's floor: one small message from one session of
this process to another through the router, at 30 Hz. Every bridge leg above contains two
such hops (sim -> bridge, bridge -> listener); on a shared machine their tail is the
scheduler's, not the bridge's.

Modules: ``bridge_rig`` (Postgres, router, the world and the bridge process), ``player`` (the
sim's side: payloads and their publisher), ``row_latency`` (notifications received, rows read
back, the latencies they give), ``legs`` (the measured legs), ``leg_report`` (figures and the
text report), ``__main__`` (the command line and the run).
"""
