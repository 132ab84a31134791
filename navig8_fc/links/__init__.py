"""The links layer: MAVLink on the wire, below both processes (docs/architecture.md).

- `transport`: UDP, TCP and serial endpoints chosen by a connection string.
- `mavlink_link`: framing, decoding with counters, peers, sending (`UdpLink`), binding, the ports file.
- `signing`: MAVLink 2 message signing on the GCS links (replays checked against one stream table, kept across
  restarts), SETUP_SIGNING redaction for the log.
- `reflection`: at most twice the bytes in go out to an address the link cannot vouch for.
- `sim_guard`: the sim link's pairing with one bridge, step sequencing and sensor validation.

The FC's shell and the physics bridge both import from here; this package imports only the standard library,
third-party packages (pymavlink, pyserial) and `navig8_fc.mavlink` (dialect, codec, seam), never the FC's
shell, flight stack, GCS handlers or core (tests/unit/test_layering.py).
"""
