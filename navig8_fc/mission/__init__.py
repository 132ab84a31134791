"""Missions: plans and their validation (plan), the MAVLink mission microservice (protocol) and the plans'
persistence (store)."""
