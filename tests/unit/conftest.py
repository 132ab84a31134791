"""Fixtures shared by the plant tests."""

from __future__ import annotations

import pytest

from navig8_fc.core.vehicle import VehicleConfig
from sim_bridge import PlantParams


@pytest.fixture(scope="module")
def cfg() -> VehicleConfig:
    return VehicleConfig.load()


@pytest.fixture(scope="module")
def params() -> PlantParams:
    """Noise-free plant parameters (a test module may override this fixture, e.g. to keep the noise)."""
    return PlantParams.load().without_noise()
