"""MAVLink for Navig8: the private dialect (navig8.xml, generated with mavgen on first use), the codec and the
bridge seam.

- `dialect`: `load()` the generated module, `new_mav(sysid, compid)` (pymavlink, for the GCS links and tests).
- `codec`: the one framer/parser of the messages Navig8 handles itself, built from the dialect's classes.
- `seam`: the lockstep contracts: step bundle, actuator answer, arm command, status (docs/bridge.md).

No sockets here: the processes (sim_bridge/bridge.py, navig8_fc/shell/) own the I/O.
"""
