"""The ground-station side of the flight controller, as pure message-in -> messages-out code.

params (parameter protocol), commands (COMMAND_LONG/INT), misc (MAVFTP NAK, empty mission, TIMESYNC),
telemetry (stream scheduler and message builders), battery (simulated pack), statustext. Every function
takes the time it needs as an argument and returns pymavlink message objects for the shell to send;
nothing here opens a socket or reads a clock. docs/gcs.md describes the behaviour a GCS sees.
"""
