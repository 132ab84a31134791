"""MAVLink for Navig8: the private dialect (navig8.xml, generated with mavgen on first use) and the bridge seam.

- `dialect`: `load()` the generated module, `new_mav(sysid, compid)`.
- `seam`: pure encode/decode of the lockstep step datagram and the actuator answer (docs/bridge.md).

No sockets here: the processes (sim_bridge/bridge.py, navig8_fc/shell/) own the I/O.
"""
