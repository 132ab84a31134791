"""Missions: plans and their validation (plan), the executor's geodesy and fence, and the plans' persistence (store).
The MAVLink mission microservice that serves them is a GCS piece: navig8_fc.gcs.mission_protocol."""
